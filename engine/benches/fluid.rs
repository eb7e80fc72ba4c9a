//! Fluid throughput: the 3D dam break of PERFORMANCE.md (a 1 x 2 x 1 m
//! column, steps of 1/240 s) at about 15k and 150k particles, WCSPH and
//! DFSPH, on one thread and on all cores. Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench fluid
//!
//! `-- peers [warm-up steps] [timed steps] [spacings…]` instead runs only the DFSPH
//! scene of `scripts/bench-peers` (solid walls, h = 2 spacing, 0.1 %
//! tolerances, fixed steps) on one thread at both sizes, timed in CPU
//! seconds so that other jobs on a shared machine do not count, with the
//! solver's iterations and errors and the time of each stage: the figures
//! to compare with the peers' table in README (defaults 24 and 24, the
//! window 0.1 to 0.2 s; spacings 0.05 and 0.0237, about 16k and 148k
//! particles).
//!
//! The peers (SPlisHSPlasH, salva3d) run beside meshless in `bench/peers`
//! (`scripts/bench-peers`); see README.

use meshless_engine::scene::{SolverKind, SystemSpec};
use meshless_engine::{BuildOptions, Scene};
use std::time::Instant;

mod common;
#[path = "common/smoke.rs"]
mod smoke;

/// The dam break at a given spacing and solver.
fn scene(spacing: f64, solver: SolverKind) -> Scene {
    let mut scene = common::dam_break(spacing);
    let SystemSpec::Fluid(fluid) = &mut scene.systems[0] else {
        panic!("the first system is the fluid")
    };
    fluid.solver = solver;
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

/// The DFSPH dam break of `bench/peers` at `spacing`.
fn peers_scene(spacing: f64) -> Scene {
    let text = format!(
        r#"
[domain]
min = [0.0, 0.0, 0.0]
max = [4.0, 3.0, 1.0]
[time]
dt = 0.004166666666666667
max_substeps = 1
[[systems]]
kind = "fluid"
solver = "dfsph"
spacing = {spacing}
support_radius = {h}
density_tolerance = 0.001
divergence_tolerance = 0.001
max_solver_iterations = 100
density_kernel = "cubic_spline"
gradient_kernel = "cubic_spline"
xsph = 0.0
viscosity = 0.0
walls = "solid"
[[systems.blocks]]
region = {{ min = [0.0, 0.0, 0.0], max = [1.0, 2.0, 1.0] }}
"#,
        h = 2.0 * spacing
    );
    Scene::from_toml_str(&text).expect("peers scene")
}

/// CPU seconds of this process's threads (`/proc/self/task/*/schedstat`),
/// 0 where the file system does not provide them.
fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0.0;
    };
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .sum::<f64>()
        * 1e-9
}

/// The `peers` mode (see the module comment).
fn peers(warmup: usize, steps: usize, spacings: &[f64]) {
    println!(
        "particles  steps  per core (per CPU-s)  pressure it./step  divergence it./step  solver density error  measured density error  mean density / rest  stages [CPU-s]"
    );
    for &spacing in spacings {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("thread pool");
        pool.install(|| {
            let mut world = peers_scene(spacing)
                .build(&BuildOptions::default())
                .expect("valid");
            for _ in 0..warmup {
                world.step().expect("stable");
            }
            let before = world.stages().clone();
            let (mut cpu, mut pressure, mut divergence) = (0.0, 0u32, 0u32);
            let (mut solver_error, mut measured, mut mean) = (0.0, 0.0, 0.0);
            for _ in 0..steps {
                let start = cpu_seconds();
                world.step().expect("stable");
                cpu += cpu_seconds() - start;
                let fluid = world.fluid().expect("fluid");
                let solve = fluid.last_solve();
                pressure += solve.density_iterations;
                divergence += solve.divergence_iterations;
                solver_error += solve.density_error;
                let rest = fluid.params.eos.rest_density;
                measured += fluid
                    .densities
                    .iter()
                    .map(|rho| (rho / rest - 1.0).max(0.0))
                    .sum::<f64>()
                    / fluid.len() as f64;
                mean += fluid.densities.iter().sum::<f64>() / (rest * fluid.len() as f64);
            }
            let n = world.particle_count();
            let stages: Vec<String> = world
                .stages()
                .iter()
                .zip(before.iter())
                .map(|((stage, after), (_, before))| (stage.name(), after.seconds - before.seconds))
                .filter(|(_, s)| *s > 0.0)
                .map(|(name, s)| format!("{name} {s:.2}"))
                .collect();
            let steps_f = steps as f64;
            println!(
                "{n:>9}  {steps:>5}  {:>20.3e}  {:>17.2}  {:>19.2}  {:>18.3} %  {:>20.3} %  {:>19.4}  {}",
                n as f64 * steps_f / cpu,
                f64::from(pressure) / steps_f,
                f64::from(divergence) / steps_f,
                100.0 * solver_error / steps_f,
                100.0 * measured / steps_f,
                mean / steps_f,
                stages.join(", ")
            );
        });
    }
}

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    if args.first().map(String::as_str) == Some("peers") {
        let number =
            |k: usize, default| args.get(k).and_then(|a| a.parse().ok()).unwrap_or(default);
        let spacings: Vec<f64> = args.iter().skip(3).filter_map(|a| a.parse().ok()).collect();
        let spacings = if spacings.is_empty() {
            smoke::pick(vec![0.05, 0.0237], vec![0.2])
        } else {
            spacings
        };
        peers(
            number(1, smoke::pick(24, 1)),
            number(2, smoke::pick(24, 1)),
            &spacings,
        );
        return;
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "solver  particles  threads  sub-steps  particle-sub-steps/s  per core   neighbour pairs/s  iterations/sub-step  density error"
    );
    let mut per_core_small = None;
    // Smoke mode: two tiny columns (250 and 468 particles), so that the
    // line comparing the sizes runs too.
    let sizes = smoke::pick(vec![(0.05, 20), (0.0237, 6)], vec![(0.2, 1), (0.15, 1)]);
    for (spacing, steps) in sizes {
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
