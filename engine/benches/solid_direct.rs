//! The implicit solid's two Newton linear solvers on bending, where CG's
//! conditioning is worst.
//!
//! **2D**: a 1 m x 0.1 m cantilever (E = 1.5e8 Pa, rho = 1000 kg/m^3,
//! Poisson 0, linear MLS, support 2 dx, hourglass 0.1) clamped by three
//! anchored columns behind x = 0, under gravity, at dx = 0.025, 0.0125
//! and 0.00625 (4, 8 and 16 particles across).
//! One step from rest at dt = 0.02 s (dynamic) and at dt = 100 s (one
//! step is the static solve), for CG and Cholesky: Newton and CG
//! iterations, final relative residual, wall time, and the tip deflection
//! (mean y displacement of the last column) against Euler–Bernoulli's
//! `q L^4 / (8 E I)`, `q = rho g H`, `I = H^3 / 12`. Then 50 steps of
//! 0.02 s each (backward Euler has damped the vibration by then): the
//! iterations summed, the worst residual and the settled deflection.
//!
//! **3D**: a 0.5 x 0.1 x 0.1 m bar clamped the same way, one dt = 0.02 s
//! step per spacing: time per Newton step, the Cholesky factor's memory
//! and the process's peak memory, to show where the direct solver stops
//! being practical.
//!
//! Prints tables; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench solid_direct          # all
//!     cargo bench -p meshless-engine --bench solid_direct -- 2d    # or 3d

use meshless_engine::approx::mls::Order;
use meshless_engine::math::{Real, Vector};
use meshless_engine::solid::{
    ElasticSolid, ImplicitParams, Integrator, LinearSolver, Material, Obstacles, SolidParams,
};
use std::time::Instant;

#[path = "common/smoke.rs"]
mod smoke;

const YOUNG: Real = 1.5e8;
const DENSITY: Real = 1000.0;
const LENGTH: Real = 1.0;
const DEPTH: Real = 0.1;
const GRAVITY: Real = 9.81;

/// Cells of size `dx` filling `[lo, hi]`, by their centres.
fn centres(lo: Real, hi: Real, dx: Real) -> Vec<Real> {
    let count = ((hi - lo) / dx).round() as usize;
    (0..count).map(|i| lo + (i as Real + 0.5) * dx).collect()
}

/// A beam of length `length` along x and cross-section `depth` (square in
/// 3D), clamped by three anchored layers behind x = 0.
fn beam(dim: usize, dx: Real, length: Real, solver: LinearSolver) -> ElasticSolid {
    let params = SolidParams {
        dim,
        spacing: dx,
        density: DENSITY,
        young: YOUNG,
        material: Material::from_young_poisson(YOUNG, 0.0, 0.0),
        order: Order::Linear,
        support: 2.0 * dx,
        hourglass: 0.1,
        damping: 0.0,
        friction: 0.0,
        integrator: Integrator::Implicit(ImplicitParams {
            linear_solver: solver,
            ..ImplicitParams::default()
        }),
        plasticity: None,
        fracture: None,
    };
    let across = centres(-0.5 * DEPTH, 0.5 * DEPTH, dx);
    let zs = if dim == 2 { vec![0.0] } else { across.clone() };
    let mut rest = Vec::new();
    for &x in &centres(-3.0 * dx, length, dx) {
        for &y in &across {
            for &z in &zs {
                rest.push(Vector::new(x, y, z));
            }
        }
    }
    let n = rest.len();
    let fixed = rest.iter().map(|x| x.x < 0.0).collect();
    ElasticSolid::new(
        params,
        rest,
        vec![Vector::zeros(); n],
        fixed,
        Obstacles::default(),
    )
    .expect("valid beam")
}

/// Mean downward displacement of the last column, m.
fn tip_deflection(solid: &ElasticSolid, length: Real) -> Real {
    let dx = solid.params.spacing;
    let (sum, count) = solid
        .positions
        .iter()
        .zip(solid.rest_positions())
        .filter(|(_, r)| r.x > length - dx)
        .fold((0.0, 0), |(s, c), (x, r)| (s + r.y - x.y, c + 1));
    sum / count as Real
}

fn name(solver: LinearSolver) -> &'static str {
    match solver {
        LinearSolver::ConjugateGradient => "CG",
        LinearSolver::Cholesky => "Cholesky",
        LinearSolver::Auto => "auto",
    }
}

/// Peak resident memory of this process, MiB (Linux only; 0 elsewhere).
fn peak_mib() -> Real {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<Real>().ok())
        })
        .map_or(0.0, |kib| kib / 1024.0)
}

fn cantilever() {
    let inertia = DEPTH.powi(3) / 12.0;
    let q = DENSITY * GRAVITY * DEPTH;
    let theory = q * LENGTH.powi(4) / (8.0 * YOUNG * inertia);
    let g = Vector::new(0.0, -GRAVITY, 0.0);
    println!("2D cantilever, Euler-Bernoulli tip deflection {theory:.5e} m");
    println!(
        "{:>7} {:>9} {:>8} {:>9} {:>6} {:>6} {:>9} {:>8} {:>8} {:>11} {:>6}",
        "dx",
        "particles",
        "solver",
        "dt",
        "newton",
        "cg",
        "residual",
        "fallback",
        "wall s",
        "tip m",
        "/EB"
    );
    // Smoke mode: the coarsest beam, two steps of the settling run.
    for dx in smoke::pick(vec![0.025, 0.0125, 0.00625], vec![0.025]) {
        for solver in [LinearSolver::ConjugateGradient, LinearSolver::Cholesky] {
            for dt in [0.02, 100.0] {
                let mut solid = beam(2, dx, LENGTH, solver);
                let start = Instant::now();
                let step = solid.step(dt, &g, 1);
                let wall = start.elapsed().as_secs_f64();
                let tip = tip_deflection(&solid, LENGTH);
                println!(
                    "{dx:>7} {:>9} {:>8} {dt:>9} {:>6} {:>6} {:>9.2e} {:>8} {wall:>8.3} {tip:>11.4e} {:>6.3}",
                    solid.len(),
                    name(solver),
                    step.newton_iterations,
                    step.iterations - step.newton_iterations,
                    step.residual,
                    step.cholesky_fallbacks,
                    tip / theory
                );
            }
        }
        for solver in [LinearSolver::ConjugateGradient, LinearSolver::Cholesky] {
            let mut solid = beam(2, dx, LENGTH, solver);
            let start = Instant::now();
            let steps = smoke::pick(50, 2);
            let (mut newton, mut cg, mut worst) = (0, 0, 0.0 as Real);
            for _ in 0..steps {
                let step = solid.step(0.02, &g, 1);
                newton += step.newton_iterations;
                cg += step.iterations - step.newton_iterations;
                worst = worst.max(step.residual);
            }
            let wall = start.elapsed().as_secs_f64();
            let tip = tip_deflection(&solid, LENGTH);
            println!(
                "{dx:>7} {:>9} {:>8} {steps} steps of 0.02 s: {newton} Newton, {cg} CG, worst \
                 residual {worst:.2e}, {wall:.3} s, tip {tip:.4e} m = {:.3} EB",
                solid.len(),
                name(solver),
                tip / theory
            );
        }
    }
}

fn bar() {
    let g = Vector::new(0.0, -GRAVITY, 0.0);
    let dt = 0.02;
    println!("\n3D bar 0.5 x 0.1 x 0.1 m, one step of {dt} s");
    println!(
        "{:>7} {:>9} {:>8} {:>6} {:>6} {:>9} {:>11} {:>10} {:>10} {:>9}",
        "dx",
        "particles",
        "solver",
        "newton",
        "cg",
        "residual",
        "s / newton",
        "factor MiB",
        "peak MiB",
        "tip m"
    );
    for dx in smoke::pick(vec![0.02, 0.0125, 0.01, 0.008], vec![0.02]) {
        for solver in [LinearSolver::Cholesky, LinearSolver::ConjugateGradient] {
            let mut solid = beam(3, dx, 0.5, solver);
            let start = Instant::now();
            let step = solid.step(dt, &g, 1);
            let wall = start.elapsed().as_secs_f64();
            println!(
                "{dx:>7} {:>9} {:>8} {:>6} {:>6} {:>9.2e} {:>11.3} {:>10.1} {:>10.0} {:>9.3e}",
                solid.len(),
                name(solver),
                step.newton_iterations,
                step.iterations - step.newton_iterations,
                step.residual,
                wall / step.newton_iterations.max(1) as Real,
                solid.cholesky_factor_bytes() as Real / (1024.0 * 1024.0),
                peak_mib(),
                tip_deflection(&solid, 0.5)
            );
        }
    }
}

fn main() {
    let only: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    let wants = |case: &str| only.is_empty() || only.iter().any(|a| a == case);
    println!(
        "{} threads",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    if wants("2d") {
        cantilever();
    }
    if wants("3d") {
        bar();
    }
}
