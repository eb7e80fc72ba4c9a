//! MLS gradients for Lagrangian solids: the one-off precomputation of
//! per-particle gradient weights (`LagrangianGradients::build`) and one
//! displacement-gradient pass (`vector_gradients`), on jittered cubic
//! lattices of about 1k, 10k and 100k particles (support h = 2 spacings,
//! about 33 neighbours), for the direct Eq. 37-38 weights at orders 1
//! and 2 and the shape-function gradients at order 2, on one thread and
//! on all cores. Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench mls

use meshless_engine::approx::{GradientKind, LagrangianGradients, Mls, MlsParams, Order};
use meshless_engine::neighbors::{CandidateSearch, NeighborList, UniformGrid};
use nalgebra::{Matrix3, Vector3};
use std::time::Instant;

#[path = "common/lattice.rs"]
mod lattice;
use lattice::lattice;

#[path = "common/smoke.rs"]
mod smoke;

type Vector = Vector3<f64>;

/// Median seconds of `run` over `repeats` runs.
fn median(repeats: usize, mut run: impl FnMut()) -> f64 {
    let mut seconds: Vec<f64> = (0..repeats)
        .map(|_| {
            let start = Instant::now();
            run();
            start.elapsed().as_secs_f64()
        })
        .collect();
    seconds.sort_by(f64::total_cmp);
    seconds[repeats / 2]
}

fn main() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut threads = vec![1];
    if cores > 1 {
        threads.push(cores);
    }
    let h = 2.0;
    let cases = [
        (Order::Linear, GradientKind::Direct),
        (Order::Quadratic, GradientKind::Direct),
        (Order::Quadratic, GradientKind::ShapeFunctions),
    ];
    println!(
        "{:>9} {:>6} {:<9} {:<14} {:>7} {:>13} {:>9} {:>13} {:>8}",
        "particles",
        "pairs/p",
        "order",
        "kind",
        "threads",
        "precompute ms",
        "us/part",
        "gradient ms",
        "ns/pair"
    );
    let mut seed = 7;
    // Smoke mode: the 1k lattice only, each timing once.
    for count in smoke::pick(vec![10, 22, 46], vec![10]) {
        let positions = lattice(count, &mut seed);
        let n = positions.len();
        let pad = Vector::repeat(1.0);
        let max = Vector::repeat(count as f64) + pad;
        let mut grid = UniformGrid::new(-pad, max, h).expect("bench grid");
        grid.rebuild(&positions);
        let mut list = NeighborList::default();
        list.build(&grid, &positions, h);
        let pairs = list.pair_count();
        let a = Matrix3::new(0.01, 0.002, 0.0, -0.003, 0.02, 0.001, 0.0, 0.004, -0.01);
        let displacement: Vec<Vector> = positions.iter().map(|x| a * x).collect();
        let mut gradients = vec![Matrix3::zeros(); n];
        for (order, kind) in cases {
            let mls = Mls::new(3, MlsParams::new(order, h)).expect("bench parameters");
            for &t in &threads {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(t)
                    .build()
                    .expect("thread pool");
                let (pre_s, pass_s) = pool.install(|| {
                    let mut pre = None;
                    let pre_s = median(smoke::pick(3, 1), || {
                        pre = Some(
                            LagrangianGradients::build(&mls, kind, &positions, &list)
                                .expect("precompute"),
                        );
                    });
                    let pre = pre.expect("built");
                    let pass_s = median(smoke::pick(7, 1), || {
                        pre.vector_gradients(&displacement, &mut gradients)
                    });
                    (pre_s, pass_s)
                });
                println!(
                    "{:>9} {:>6.1} {:<9} {:<14} {:>7} {:>13.1} {:>9.2} {:>13.2} {:>8.2}",
                    n,
                    pairs as f64 / n as f64,
                    format!("{order:?}"),
                    format!("{kind:?}"),
                    t,
                    pre_s * 1e3,
                    pre_s * 1e6 / n as f64,
                    pass_s * 1e3,
                    pass_s * 1e9 / pairs as f64
                );
            }
        }
    }
}
