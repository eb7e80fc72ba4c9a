//! Elastic solid steps per second: a 3D block of about 1k, 10k and 100k
//! particles (support 2 spacings, about 33 neighbours, linear MLS,
//! hourglass control on), explicit sub-steps at the stability limit and
//! implicit steps at 100 times it (conjugate gradients, and at 1k also
//! sparse Cholesky, which `auto` leaves to 2D), on one thread and on all
//! cores. The
//! block starts stretched by 1 % and vibrates, so every pass does real
//! work. Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench solid
//!
//! For scale, Müller et al. 2004 report 27 frames/s for 200 particles
//! (with a 10k-point surface) on a 2.8 GHz Pentium 4.

use meshless_engine::approx::mls::Order;
use meshless_engine::geometry::Shape;
use meshless_engine::math::Vector;
use meshless_engine::solid::{
    ElasticSolid, ImplicitParams, Integrator, LinearSolver, Material, Obstacles, SolidParams,
};
use std::time::Instant;

#[path = "common/smoke.rs"]
mod smoke;

fn block(side: usize, integrator: Integrator) -> ElasticSolid {
    let spacing = 0.01;
    let young = 1e6;
    let params = SolidParams {
        dim: 3,
        spacing,
        density: 1000.0,
        young,
        material: Material::from_young_poisson(young, 0.3, 0.0),
        order: Order::Linear,
        support: 2.0 * spacing,
        hourglass: 0.1,
        damping: 0.0,
        friction: 0.0,
        integrator,
        plasticity: None,
        fracture: None,
    };
    let half = 0.5 * side as f64 * spacing;
    let rest = Shape::Box {
        half_extents: Vector::repeat(half),
    }
    .sample_volume(spacing, 3)
    .expect("block");
    let n = rest.len();
    let mut solid = ElasticSolid::new(
        params,
        rest,
        vec![Vector::zeros(); n],
        vec![false; n],
        Obstacles::default(),
    )
    .expect("solid");
    let stretched: Vec<Vector> = solid
        .rest_positions()
        .iter()
        .map(|x| Vector::new(1.01 * x.x, x.y, x.z))
        .collect();
    solid
        .set_state(stretched, vec![Vector::zeros(); n])
        .expect("state");
    solid
}

fn main() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut threads = vec![1];
    if cores > 1 {
        threads.push(cores);
    }
    println!(
        "{:>9} {:>17} {:>7} {:>12} {:>10} {:>12} {:>14}",
        "particles", "method", "threads", "steps/s", "ms/step", "ns/particle", "Newton+CG its"
    );
    let gravity = Vector::zeros();
    // Smoke mode: a block of some 200 particles (explicit, CG and Cholesky),
    // one step of each.
    for side in smoke::pick(vec![10, 22, 46], vec![6]) {
        for &t in &threads {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("pool");
            pool.install(|| {
                let mut solid = block(side, Integrator::Explicit { cfl: 0.5 });
                let n = solid.len();
                let dt = solid.params.stable_dt(0.5);
                let substeps = smoke::pick((2_000_000 / n).clamp(5, 400), 1);
                solid.step(dt, &gravity, 1);
                let start = Instant::now();
                for _ in 0..substeps {
                    solid.step(dt, &gravity, 1);
                }
                let seconds = start.elapsed().as_secs_f64() / substeps as f64;
                println!(
                    "{:>9} {:>17} {:>7} {:>12.1} {:>10.3} {:>12.1} {:>14}",
                    n,
                    "explicit",
                    t,
                    1.0 / seconds,
                    seconds * 1e3,
                    seconds * 1e9 / n as f64,
                    "-"
                );
                let solvers: &[(LinearSolver, &str)] = match n {
                    0..=2_000 => &[
                        (LinearSolver::ConjugateGradient, "implicit CG"),
                        (LinearSolver::Cholesky, "implicit Cholesky"),
                    ],
                    2_001..=20_000 => &[(LinearSolver::ConjugateGradient, "implicit CG")],
                    _ => &[],
                };
                for &(linear_solver, label) in solvers {
                    let settings = ImplicitParams {
                        linear_solver,
                        ..ImplicitParams::default()
                    };
                    let mut solid = block(side, Integrator::Implicit(settings));
                    let steps = smoke::pick(3, 1);
                    let start = Instant::now();
                    let mut iterations = 0;
                    for _ in 0..steps {
                        iterations += solid.step(100.0 * dt, &gravity, 1).iterations;
                    }
                    let seconds = start.elapsed().as_secs_f64() / steps as f64;
                    println!(
                        "{:>9} {:>17} {:>7} {:>12.1} {:>10.3} {:>12.1} {:>14}",
                        n,
                        label,
                        t,
                        1.0 / seconds,
                        seconds * 1e3,
                        seconds * 1e9 / n as f64,
                        iterations / steps
                    );
                }
            });
        }
    }
}
