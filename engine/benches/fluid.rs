//! Fluid throughput: the 3D dam break of PERFORMANCE.md (a 1 x 2 x 1 m
//! column, steps of 1/240 s) at about 15k and 150k particles, WCSPH and
//! DFSPH, on one thread and on all cores. Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench fluid
//!
//! The peers (SPlisHSPlasH, salva3d) run beside meshless in `bench/peers`
//! (`scripts/bench-peers`); see README.

use meshless_engine::approx::KernelKind;
use meshless_engine::scene::{SolverKind, SystemSpec};
use meshless_engine::{BuildOptions, Scene};
use std::time::Instant;

/// The dam break at a given spacing, solver and kernel pair.
fn scene(spacing: f64, solver: SolverKind) -> Scene {
    let text = format!(
        r#"
[domain]
min = [0.0, 0.0, 0.0]
max = [4.0, 3.0, 1.0]
[time]
dt = 0.004166666666666667
[[systems]]
kind = "fluid"
spacing = {spacing}
stiffness = 5.7e5
xsph = 0.0
[[systems.blocks]]
region = {{ min = [0.0, 0.0, 0.0], max = [1.0, 2.0, 1.0] }}
"#
    );
    let mut scene = Scene::from_toml_str(&text).expect("bench scene");
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.solver = solver;
    fluid.density_kernel = KernelKind::CubicSpline;
    fluid.gradient_kernel = KernelKind::CubicSpline;
    scene
}

struct Measured {
    particles: usize,
    substeps: u64,
    seconds: f64,
    pairs: f64,
    iterations: u64,
    density_error: f64,
}

/// Runs `steps` steps after as many again let the column start to fall
/// (so the pressure solver has work to do).
fn measure(scene: &Scene, steps: usize) -> Measured {
    let mut world = scene.build(&BuildOptions::default()).expect("valid");
    for _ in 0..steps {
        world.step().expect("stable");
    }
    let (mut substeps, mut pairs, mut iterations, mut density_error) = (0u64, 0.0, 0u64, 0.0f64);
    let start = Instant::now();
    for _ in 0..steps {
        let info = world.step().expect("stable");
        substeps += u64::from(info.substeps);
        iterations += u64::from(info.solver_iterations);
        density_error = density_error.max(info.density_error);
        pairs += world.fluid().expect("fluid").neighbor_pairs() as f64 * f64::from(info.substeps);
    }
    Measured {
        particles: world.particle_count(),
        substeps,
        seconds: start.elapsed().as_secs_f64(),
        pairs,
        iterations,
        density_error,
    }
}

fn main() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "solver  particles  threads  sub-steps  particle-sub-steps/s  per core   neighbour pairs/s  iterations/sub-step  density error"
    );
    let mut per_core_small = None;
    for (spacing, steps) in [(0.05, 20), (0.0237, 6)] {
        for solver in [SolverKind::Wcsph, SolverKind::Dfsph] {
            let scene = scene(spacing, solver);
            for threads in [1, cores] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("thread pool");
                let m = pool.install(|| measure(&scene, steps));
                let rate = m.particles as f64 * m.substeps as f64 / m.seconds;
                let per_core = rate / threads as f64;
                println!(
                    "{:<7} {:>9}  {:>7}  {:>9}  {:>20.3e}  {:>8.3e}  {:>17.3e}  {:>19.2}  {:>11.3} %",
                    format!("{solver:?}").to_lowercase(),
                    m.particles,
                    threads,
                    m.substeps,
                    rate,
                    per_core,
                    m.pairs / m.seconds,
                    m.iterations as f64 / m.substeps as f64,
                    100.0 * m.density_error
                );
                if threads == 1 && solver == SolverKind::Wcsph {
                    match per_core_small {
                        None => per_core_small = Some((m.particles, per_core)),
                        Some((n, small)) => println!(
                            "        cost per particle-sub-step from {n} to {} particles: x{:.2} (1.00 is linear)",
                            m.particles,
                            small / per_core
                        ),
                    }
                }
            }
        }
    }
}
