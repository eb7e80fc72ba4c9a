//! The dam break in meshless: its DFSPH with the cubic spline pair and
//! the tabulated solid box walls (engine/src/fluid/walls.rs).

use crate::setup::{DamBreak, Run, cpu_seconds};
use meshless_engine::stats::StageTimer;
use meshless_engine::{BuildOptions, Scene};
use std::time::Instant;

/// The scene: `max_substeps = 1` holds every step at `dt`, as the peers'
/// fixed steps; steps the CFL limit would have split are counted.
pub fn scene(d: &DamBreak) -> Scene {
    let ((lo, hi), (cmin, cmax)) = (d.domain, d.column);
    let text = format!(
        r#"
name = "peer benchmark dam break"
[domain]
min = {lo:?}
max = {hi:?}
[time]
dt = {dt}
max_substeps = 1
[[systems]]
kind = "fluid"
solver = "dfsph"
spacing = {spacing}
support_radius = {h}
rest_density = {rest}
density_tolerance = {tol}
divergence_tolerance = {div}
max_solver_iterations = {iters}
density_kernel = "cubic_spline"
gradient_kernel = "cubic_spline"
xsph = 0.0
viscosity = 0.0
walls = "solid"
[[systems.blocks]]
region = {{ min = {cmin:?}, max = {cmax:?} }}
"#,
        dt = d.dt,
        spacing = d.spacing,
        h = d.support_radius(),
        rest = d.rest_density,
        tol = d.tolerance,
        div = d.divergence_tolerance,
        iters = d.max_iterations,
    );
    Scene::from_toml_str(&text).expect("the benchmark scene is valid")
}

/// Steps the warm-up, then times `d.steps` steps on the current rayon pool.
/// Returns the run and how many timed steps the stability limit would have
/// split.
pub fn run(d: &DamBreak, threads: usize) -> (Run, u32) {
    let mut world = scene(d)
        .build(&BuildOptions::default())
        .expect("the benchmark scene builds");
    for _ in 0..d.warmup {
        world.step().expect("stable warm-up");
    }
    let before: StageTimer = world.stages().clone();
    let n = world.particle_count();
    let (mut seconds, mut cpu, mut pairs) = (0.0, 0.0, 0.0);
    let (mut density_error, mut mean_density, mut solver_error) = (0.0, 0.0, 0.0);
    let (mut pressure, mut divergence, mut capped) = (0u64, 0u64, 0u32);
    for _ in 0..d.steps {
        let (start, start_cpu) = (Instant::now(), cpu_seconds());
        let info = world.step().expect("stable step");
        seconds += start.elapsed().as_secs_f64();
        cpu += cpu_seconds() - start_cpu;
        let fluid = world.fluid().expect("a fluid");
        let solve = fluid.last_solve();
        pressure += u64::from(solve.density_iterations);
        divergence += u64::from(solve.divergence_iterations);
        solver_error += solve.density_error;
        capped += u32::from(info.capped);
        // The lists count each particle as its own neighbour.
        pairs += (fluid.neighbor_pairs() - n) as f64;
        let (compression, mean) =
            Run::density_stats(fluid.densities.iter().copied(), d.rest_density);
        density_error += compression;
        mean_density += mean;
    }
    let steps = d.steps as f64;
    let stages = world
        .stages()
        .iter()
        .zip(before.iter())
        .map(|((stage, after), (_, before))| (stage.name(), after.seconds - before.seconds))
        .filter(|(_, s)| *s > 0.0)
        .collect();
    let run = Run {
        engine: "meshless",
        particles: n,
        threads,
        steps: d.steps,
        seconds,
        cpu_seconds: cpu,
        fluid_pairs: pairs,
        pressure_iterations: Some(pressure),
        divergence_iterations: Some(divergence),
        solver_error: Some(solver_error / steps),
        density_error: density_error / steps,
        mean_density: mean_density / steps,
        stages,
    };
    (run, capped)
}
