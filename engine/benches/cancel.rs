//! How soon a step stops once its cancel flag goes up: the longest work
//! the engine does between two reads of the flag, for the loops a Pause,
//! a deletion or an abandoned `Step` has to wait out. The engine reads
//! the flag every fluid sub-step, every DFSPH pressure iteration, every
//! Newton and CG iteration of an implicit solid; what lies between two
//! reads (a sub-step's particle passes, one sparse Cholesky
//! factorisation) cannot be interrupted.
//!
//! Each case builds a world whose one step would run for minutes (many
//! sub-steps, or tolerances no solve reaches), steps it on this thread,
//! raises the flag from another at a few moments into the step, and
//! prints the longest and the median time from the flag to the step's
//! return. Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench cancel

use meshless_engine::{BuildOptions, Cancel, Scene, World};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

#[path = "common/smoke.rs"]
mod smoke;

/// A 3D block of fluid, `side` particles along x and y and half that
/// along z, in one step of 10 s: thousands of sub-steps for WCSPH, and
/// for DFSPH sub-steps of 10,000 pressure iterations each (tolerances at
/// their floor, which a resting block does not reach).
fn fluid(side: usize, solver: &str) -> String {
    let spacing = 1.0 / side as f64;
    format!(
        r#"
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [1.2, 1.2, 0.7]
        [time]
        dt = 10.0
        max_substeps = 1000000
        [[systems]]
        kind = "fluid"
        spacing = {spacing}
        stiffness = 1000.0
        solver = "{solver}"
        density_tolerance = 1e-6
        divergence_tolerance = 1e-6
        max_solver_iterations = 10000
        [[systems.blocks]]
        region = {{ min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 0.5] }}
        "#
    )
}

/// A stiff 3D cube of `side`^3 particles stepped implicitly with
/// tolerances no solve reaches, by `linear_solver`.
fn solid(side: usize, linear_solver: &str) -> String {
    let spacing = 0.4 / side as f64;
    let half = 0.5 * (side as f64 - 1.0) * spacing + 0.1 * spacing;
    format!(
        r#"
        [domain]
        min = [-1.0, -1.0, -1.0]
        max = [1.0, 1.0, 1.0]
        [time]
        dt = 0.05
        [[systems]]
        kind = "solid"
        shape = {{ type = "box", half_extents = [{half}, {half}, {half}] }}
        position = [0.0, 0.0, 0.0]
        spacing = {spacing}
        young = 1e6
        integrator = "implicit"
        [systems.implicit]
        newton_tolerance = 1e-300
        max_newton_iterations = 100000
        cg_tolerance = 1e-300
        max_cg_iterations = 100000
        linear_solver = "{linear_solver}"
        "#
    )
}

/// Steps a fresh `scene` once and raises its flag `after` into the step;
/// the time from the flag to the step's return, `None` when the step
/// ended before the flag went up (a tiny smoke-mode world may).
fn latency(scene: &Scene, after: Duration) -> Option<Duration> {
    let mut world: World = scene
        .build(&BuildOptions::default())
        .expect("a valid scene");
    let cancel = Cancel::new();
    let (raised_tx, raised) = mpsc::channel();
    let canceller = {
        let cancel = cancel.clone();
        thread::spawn(move || {
            thread::sleep(after);
            cancel.cancel();
            raised_tx.send(Instant::now()).expect("the stepper waits");
        })
    };
    let result = world.step_cancellable(&cancel);
    let returned = Instant::now();
    canceller.join().expect("the canceller ends");
    let raised = raised.recv().expect("the flag went up");
    result
        .is_err()
        .then(|| returned.saturating_duration_since(raised))
}

fn main() {
    let smoke = smoke::smoke();
    let fluid_side = smoke::pick(48, 8);
    let solid_side = smoke::pick(20, 4);
    let cholesky_side = smoke::pick(14, 4);
    let cases = [
        ("fluid, WCSPH", "sub-step", fluid(fluid_side, "wcsph")),
        (
            "fluid, DFSPH",
            "sub-step or pressure iteration",
            fluid(fluid_side, "dfsph"),
        ),
        (
            "implicit solid, CG",
            "CG iteration",
            solid(solid_side, "conjugate_gradient"),
        ),
        (
            "implicit solid, Cholesky",
            "Newton iteration (one factorisation)",
            solid(cholesky_side, "cholesky"),
        ),
    ];
    let moments: &[Duration] = if smoke {
        &[Duration::from_millis(20)]
    } else {
        &[
            Duration::from_millis(500),
            Duration::from_millis(1300),
            Duration::from_millis(2100),
            Duration::from_millis(2900),
            Duration::from_millis(3700),
        ]
    };
    println!("| work | particles | read between | flag to return, median (ms) | longest (ms) |");
    println!("|---|---|---|---|---|");
    for (name, between, text) in cases {
        let scene = Scene::from_toml_str(&text).expect("the scene parses");
        let particles = scene
            .build(&BuildOptions::default())
            .expect("a valid scene")
            .particle_count();
        let mut latencies: Vec<Duration> = moments
            .iter()
            .filter_map(|&after| latency(&scene, after))
            .collect();
        latencies.sort();
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        match (latencies.get(latencies.len() / 2), latencies.last()) {
            (Some(&median), Some(&longest)) => println!(
                "| {name} | {particles} | {between} | {:.1} | {:.1} |",
                ms(median),
                ms(longest)
            ),
            _ => println!("| {name} | {particles} | {between} | the step ended first | |"),
        }
    }
}
