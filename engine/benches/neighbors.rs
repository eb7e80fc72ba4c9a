//! Neighbour search throughput: rebuild + `NeighborList::build` for each
//! candidate search (uniform grid, spatial hash with cells of r and 2r,
//! kd-tree) on a jittered lattice of about 100k points (radius twice the
//! spacing) and on a dense clump, 50 times denser than the rest (radius
//! twice the clump's spacing: one radius must resolve the finest part),
//! on one thread and on all cores. Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench neighbors

use meshless_engine::neighbors::{
    CandidateSearch, HashCell, KdTree, NeighborList, SpatialHash, UniformGrid,
};
use nalgebra::Vector3;
use std::time::Instant;

#[path = "common/smoke.rs"]
mod smoke;

type Vector = Vector3<f64>;

/// Timed repetitions per case (1 in smoke mode); the median is reported.
fn repeats() -> usize {
    smoke::pick(7, 1)
}

/// Deterministic numbers in [0, 1) (SplitMix64).
fn uniform(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as f64 / u64::MAX as f64
}

/// A cubic lattice of `count`^3 points with `spacing`, from `origin`,
/// each jittered by up to a quarter spacing, skipping points `skip` keeps.
fn lattice(
    origin: Vector,
    count: usize,
    spacing: f64,
    seed: &mut u64,
    skip: impl Fn(&Vector) -> bool,
) -> Vec<Vector> {
    let mut points = Vec::new();
    for i in 0..count {
        for j in 0..count {
            for k in 0..count {
                let mut p = origin + Vector::new(i as f64, j as f64, k as f64) * spacing;
                for a in 0..3 {
                    p[a] += (uniform(seed) - 0.5) * 0.5 * spacing;
                }
                if !skip(&p) {
                    points.push(p);
                }
            }
        }
    }
    points
}

struct Distribution {
    name: &'static str,
    positions: Vec<Vector>,
    radius: f64,
}

fn distributions() -> Vec<Distribution> {
    let mut seed = 42;
    // Smoke mode: 8^3 points, and a 10^3 lattice with a 2^3 clump.
    let (side, sparse, clump_lo, clump_hi) = smoke::pick((46, 40, 15.0, 25.0), (8, 10, 4.0, 6.0));
    let uniform_lattice = lattice(Vector::zeros(), side, 1.0, &mut seed, |_| false);
    // Sparse lattice of spacing 1 over 40^3, with a 10^3 clump at spacing
    // 50^(-1/3) (50x the density) in place of its sparse points.
    let clump_spacing = 50f64.powf(-1.0 / 3.0);
    let (lo, hi) = (Vector::repeat(clump_lo), Vector::repeat(clump_hi));
    let inside = |p: &Vector| (0..3).all(|a| p[a] >= lo[a] && p[a] < hi[a]);
    let mut clumped = lattice(Vector::zeros(), sparse, 1.0, &mut seed, inside);
    let per_side = ((clump_hi - clump_lo) / clump_spacing).round() as usize;
    clumped.extend(lattice(lo, per_side, clump_spacing, &mut seed, |_| false));
    vec![
        Distribution {
            name: "lattice",
            positions: uniform_lattice,
            radius: 2.0,
        },
        Distribution {
            name: "clump 50x",
            positions: clumped,
            radius: 2.0 * clump_spacing,
        },
    ]
}

/// Median seconds of rebuild + build, and the pair count.
fn time<S: CandidateSearch>(search: &mut S, positions: &[Vector], radius: f64) -> (f64, usize) {
    let mut list = NeighborList::default();
    search.rebuild(positions);
    list.build(search, positions, radius);
    let repeats = repeats();
    let mut seconds: Vec<f64> = (0..repeats)
        .map(|_| {
            let start = Instant::now();
            search.rebuild(positions);
            list.build(search, positions, radius);
            start.elapsed().as_secs_f64()
        })
        .collect();
    seconds.sort_by(f64::total_cmp);
    (seconds[repeats / 2], list.pair_count())
}

fn main() {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut threads = vec![1];
    if cores > 1 {
        threads.push(cores);
    }
    println!(
        "{:<10} {:<10} {:>7} {:>7} {:>9} {:>10} {:>10}",
        "variant", "dist", "points", "threads", "build ms", "pairs", "Mpairs/s"
    );
    let mut winners = Vec::new();
    for dist in distributions() {
        let (positions, radius) = (&dist.positions, dist.radius);
        let (mut min, mut max) = (positions[0], positions[0]);
        for p in positions {
            min = min.inf(p);
            max = max.sup(p);
        }
        for &t in &threads {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("thread pool");
            let results = pool.install(|| {
                let mut grid = UniformGrid::new(min, max, radius).expect("bench grid");
                let mut hash_r = SpatialHash::new(radius, HashCell::Radius);
                let mut hash_2r = SpatialHash::new(radius, HashCell::TwiceRadius);
                let mut tree = KdTree::new(radius);
                [
                    ("grid", time(&mut grid, positions, radius)),
                    ("hash r", time(&mut hash_r, positions, radius)),
                    ("hash 2r", time(&mut hash_2r, positions, radius)),
                    ("kd-tree", time(&mut tree, positions, radius)),
                ]
            });
            for (name, (seconds, pairs)) in &results {
                println!(
                    "{:<10} {:<10} {:>7} {:>7} {:>9.1} {:>10} {:>10.1}",
                    name,
                    dist.name,
                    positions.len(),
                    t,
                    seconds * 1e3,
                    pairs,
                    *pairs as f64 / seconds / 1e6
                );
            }
            if let Some((name, _)) = results.iter().min_by(|a, b| a.1.0.total_cmp(&b.1.0)) {
                winners.push(format!("{} on {} thread(s): {name}", dist.name, t));
            }
        }
    }
    println!();
    for line in winners {
        println!("fastest, {line}");
    }
}
