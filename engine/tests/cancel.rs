//! Cancelling a step from another thread: a step that would run for a
//! long time (a large `time.dt` in many sub-steps, an implicit solid's
//! Newton and CG loops) stops within one sub-step or iteration of the
//! flag going up, leaves the world exactly as it was before the step, and
//! the same step taken again computes what an uncancelled one does.
//!
//! Each test cancels at a moment picked inside the step (a fixed delay
//! after it began: not a wait for anything, the assertions hold wherever
//! it lands) and bounds how long the step took to notice, a correctness
//! bound: the uncancelled step is many times longer.

use meshless_engine::scene::{SolverKind, SystemSpec};
use meshless_engine::stats::Stage;
use meshless_engine::{BuildOptions, Cancel, Scene, StepError, World};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

/// How far into a step the flag goes up.
const CANCEL_AFTER: Duration = Duration::from_millis(200);

/// Longest a cancelled step may take to return once the flag is up.
const LATENCY: Duration = Duration::from_secs(2);

/// A 2D tank of 30 x 30 WCSPH (or DFSPH) particles at rest, sub-stepped
/// at Courant number `cfl`.
fn tank(solver: SolverKind, dt: f64, cfl: f64) -> Scene {
    let mut scene = Scene::from_toml_str(&format!(
        r#"
        dimension = 2
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.0, 1.0, 0.0]
        [time]
        dt = {dt:e}
        max_substeps = 1000000
        cfl = {cfl}
        [output]
        fields = ["velocity", "density", "pressure"]
        [[systems]]
        kind = "fluid"
        spacing = 0.02
        stiffness = 1e4
        [[systems.blocks]]
        region = {{ min = [0.0, 0.0, 0.0], max = [0.6, 0.6, 0.0] }}
        "#
    ))
    .expect("the tank parses");
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.solver = solver;
    scene
}

fn build(scene: &Scene) -> World {
    scene
        .build(&BuildOptions::default())
        .expect("a valid scene")
}

/// How a cancelled step went.
struct Cancelled {
    result: Result<(), StepError>,
    /// From the flag going up to the step returning.
    latency: Duration,
    /// From the step beginning to the flag going up.
    before: Duration,
}

/// Steps `world` once on this thread while another raises the step's
/// flag `after` into it.
fn step_and_cancel(world: &mut World, after: Duration) -> Cancelled {
    let cancel = Cancel::new();
    let (raised_tx, raised) = mpsc::channel();
    let start = Instant::now();
    let canceller = {
        let cancel = cancel.clone();
        thread::spawn(move || {
            thread::sleep(after);
            let at = Instant::now();
            cancel.cancel();
            raised_tx.send(at).expect("the test waits");
        })
    };
    let result = world.step_cancellable(&cancel).map(|_| ());
    let returned = Instant::now();
    canceller.join().expect("the canceller ends");
    let raised = raised.recv().expect("the flag went up");
    Cancelled {
        result,
        latency: returned.saturating_duration_since(raised),
        before: raised - start,
    }
}

/// A 2D WCSPH tank whose one step needs about 50 000 sub-steps is
/// cancelled mid-step: it returns within a sub-step or so, and the
/// world's frame and clock are bit for bit those before the step.
#[test]
fn a_long_fluid_step_stops_soon_after_its_flag_and_keeps_the_world() {
    // The sub-step length, from a short probe step.
    let probe_dt = 0.01;
    // Sub-steps as long as the limit allows ring at the default Courant
    // number: a lower one keeps the long step stable.
    let cfl = 0.2;
    let mut probe = build(&tank(SolverKind::Wcsph, probe_dt, cfl));
    let probe_substeps = probe.step().expect("a stable probe step").substeps;
    let substep = probe_dt / f64::from(probe_substeps);
    let wanted = 50_000.0;
    let mut world = build(&tank(SolverKind::Wcsph, wanted * substep, cfl));
    let before = world.frame();
    let clock = world.clock();

    let outcome = step_and_cancel(&mut world, CANCEL_AFTER);

    assert_eq!(
        outcome.result,
        Err(StepError::Cancelled { step: 1 }),
        "the step was cancelled"
    );
    assert_eq!(world.clock(), clock, "the clock did not advance");
    assert_eq!(
        world.frame(),
        before,
        "the frame is the one before the step"
    );
    // The stage timer is statistics, kept through the restore: it shows
    // how far the step got.
    let stages = world.stages();
    let done = stages.get(Stage::Integrate).runs;
    let seconds: f64 = stages.iter().map(|(_, s)| s.seconds).sum();
    let full = if done > 0 {
        wanted * seconds / done as f64
    } else {
        f64::INFINITY
    };
    println!(
        "cancelled after {done} of about {wanted} sub-steps ({:?} in); returned {:?} after the \
         flag; the whole step would take about {full:.0} s",
        outcome.before, outcome.latency
    );
    let bound = LATENCY.min(Duration::from_secs_f64(full / 10.0));
    assert!(
        outcome.latency < bound,
        "took {:?} to stop, over {bound:?} (the whole step: about {full:.0} s)",
        outcome.latency
    );
}

/// The tank with a small elastic box beside it (systems[1]), steps of
/// 0.01 s (dozens of sub-steps) at the default Courant number. (At 0.05 s
/// DFSPH's first step compressed a particle to 2.5 rho_0, which now
/// faults.)
fn tank_and_box(solver: SolverKind) -> Scene {
    let mut scene = tank(solver, 0.01, 0.4);
    let solid = Scene::from_toml_str(
        r#"
        dimension = 2
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.0, 1.0, 0.0]
        [time]
        dt = 0.05
        [[systems]]
        kind = "solid"
        shape = { type = "box", half_extents = [0.1, 0.1, 0.1] }
        position = [0.8, 0.5, 0.0]
        spacing = 0.05
        young = 1e5
        "#,
    )
    .expect("the box parses");
    scene.systems.extend(solid.systems);
    scene
}

/// With either fluid solver and a solid beside the fluid: a step
/// cancelled part-way and then taken again computes bit for bit what the
/// same step computes uncancelled (the solvers' warm starts and the
/// particle sorting go back with the state), so a paused session resumes
/// on the trajectory it would have followed.
#[test]
fn a_cancelled_step_taken_again_equals_the_uncancelled_step() {
    for solver in [SolverKind::Wcsph, SolverKind::Dfsph] {
        let scene = tank_and_box(solver);
        let mut twin = build(&scene);
        // Past the start at rest, so that every state has moved.
        twin.step()
            .unwrap_or_else(|e| panic!("{solver:?}: a first step: {e}"));
        let start = Instant::now();
        twin.step().expect("the uncancelled step");
        // Cancelled half-way through the same step, by the twin's clock.
        // A step that ends before the flag goes up (a machine busier
        // while the twin stepped) proves nothing either way: try again
        // on a fresh world, sooner.
        let mut after = start.elapsed() / 2;
        let (mut world, cancelled) = loop {
            let mut world = build(&scene);
            world.step().expect("a first step");
            let cancelled = step_and_cancel(&mut world, after);
            if cancelled.result.is_ok() && after > Duration::from_micros(100) {
                after /= 2;
                continue;
            }
            break (world, cancelled);
        };
        assert_eq!(
            cancelled.result,
            Err(StepError::Cancelled { step: 2 }),
            "{solver:?}: cancelled {:?} into the step",
            cancelled.before
        );
        assert!(
            cancelled.latency < LATENCY,
            "{solver:?}: took {:?} to stop",
            cancelled.latency
        );
        world.step().expect("the step taken again");
        assert_eq!(world.clock(), twin.clock(), "{solver:?}");
        assert_eq!(world.last_step(), twin.last_step(), "{solver:?}");
        assert_eq!(
            world.frame(),
            twin.frame(),
            "{solver:?}: the step taken again differs from the uncancelled one"
        );
    }
}

/// One DFSPH sub-step solved to a density error of 1e-6 over 14 400
/// particles: thousands of iterations, seconds for the one sub-step (7 s
/// on 2 cores). The solve reads the flag every iteration, so a cancel
/// inside the sub-step is heard within one.
#[test]
fn a_dfsph_solve_stops_within_its_iterations() {
    let scene = Scene::from_toml_str(
        r#"
        dimension = 2
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.0, 1.0, 0.0]
        [time]
        dt = 0.001
        [[systems]]
        kind = "fluid"
        solver = "dfsph"
        spacing = 0.005
        density_tolerance = 1e-6
        divergence_tolerance = 1e-6
        max_solver_iterations = 10000
        [[systems.blocks]]
        region = { min = [0.0, 0.0, 0.0], max = [0.6, 0.6, 0.0] }
        "#,
    )
    .expect("the tank parses");
    let mut world = build(&scene);
    let before = world.frame();
    let outcome = step_and_cancel(&mut world, CANCEL_AFTER);
    assert_eq!(outcome.result, Err(StepError::Cancelled { step: 1 }));
    assert_eq!(world.frame(), before, "the tank is as it was");
    let substeps = world.stages().get(Stage::Integrate).runs;
    println!(
        "cancelled {:?} into the step ({substeps} integration passes); returned {:?} after \
         the flag",
        outcome.before, outcome.latency
    );
    assert!(
        outcome.latency < LATENCY,
        "took {:?} to stop",
        outcome.latency
    );
}

/// A stiff 3D block stepped implicitly with tolerances no solve reaches:
/// every Newton iteration runs CG to 100 000 iterations, so the step
/// would take minutes; cancelled, it stops within one CG iteration and
/// leaves the block where it was.
#[test]
fn an_implicit_solids_newton_and_cg_loops_stop_soon_after_the_flag() {
    let scene = Scene::from_toml_str(
        r#"
        [domain]
        min = [-1.0, -1.0, -1.0]
        max = [1.0, 1.0, 1.0]
        [time]
        dt = 0.05
        [[systems]]
        kind = "solid"
        shape = { type = "box", half_extents = [0.2, 0.2, 0.2] }
        position = [0.0, 0.0, 0.0]
        spacing = 0.05
        young = 1e6
        integrator = "implicit"
        [systems.implicit]
        newton_tolerance = 1e-300
        max_newton_iterations = 100000
        cg_tolerance = 1e-300
        max_cg_iterations = 100000
        linear_solver = "conjugate_gradient"
        "#,
    )
    .expect("the block parses");
    let mut world = build(&scene);
    let before = world.frame();
    let outcome = step_and_cancel(&mut world, CANCEL_AFTER);
    assert_eq!(outcome.result, Err(StepError::Cancelled { step: 1 }));
    assert_eq!(world.clock().step, 0);
    assert_eq!(world.frame(), before, "the block is where it was");
    println!(
        "cancelled {:?} into the step; returned {:?} after the flag",
        outcome.before, outcome.latency
    );
    assert!(
        outcome.latency < LATENCY,
        "took {:?} to stop",
        outcome.latency
    );
}
