//! Surface reconstruction cost: the frame of the PERFORMANCE.md dam-break
//! column (1 x 2 x 1 m) at about 16k and 150k particles, with and without
//! `output.surface` (cell = spacing / 2), on one thread and on all cores.
//! Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench surface

use meshless_engine::scene::SurfaceSpec;
use meshless_engine::{BuildOptions, World};
use std::time::Instant;

mod common;
#[path = "common/smoke.rs"]
mod smoke;

fn world(spacing: f64, surface: bool) -> World {
    let mut scene = common::dam_break(spacing);
    scene.output.surface = surface.then_some(SurfaceSpec {
        cell: None,
        iso: 0.5,
    });
    scene.build(&BuildOptions::default()).expect("valid")
}

/// Median seconds of `runs` frames.
fn seconds_per_frame(world: &World, runs: usize) -> f64 {
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            std::hint::black_box(world.frame());
            start.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[runs / 2]
}

fn main() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "{:>9}  {:>7}  {:>9}  {:>13}  {:>16}  {:>15}",
        "particles", "threads", "triangles", "frame [ms]", "surface [ms]", "particles/s"
    );
    let runs = smoke::pick(5, 1);
    // Smoke mode: a column of 250 particles, one frame each.
    for spacing in smoke::pick(vec![0.05, 0.0238], vec![0.2]) {
        let (plain, meshed) = (world(spacing, false), world(spacing, true));
        let triangles = meshed.frame().surface.map_or(0, |m| m.triangles.len());
        for threads in [1, cores] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a pool");
            let (without, with) = pool.install(|| {
                (
                    seconds_per_frame(&plain, runs),
                    seconds_per_frame(&meshed, runs),
                )
            });
            let surface = with - without;
            println!(
                "{:>9}  {:>7}  {:>9}  {:>13.1}  {:>16.1}  {:>15.3e}",
                meshed.particle_count(),
                threads,
                triangles,
                1e3 * without,
                1e3 * surface,
                meshed.particle_count() as f64 / surface
            );
        }
    }
}
