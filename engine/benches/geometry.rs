//! Mesh geometry cost: building a `MeshSdf` and querying it, for
//! icospheres of 1,280 to 327,680 triangles, on one thread and on all
//! cores, against a scan of every triangle (the BVH should make a query
//! grow like log n, the scan like n); then surface and volume sampling of
//! the unit sphere. Prints a table; asserts nothing.
//!
//!     cargo bench -p meshless-engine --bench geometry

use meshless_engine::geometry::{MeshSdf, TriMesh, sample_surface, sample_volume};
use meshless_engine::math::Vector;
use rayon::prelude::*;
use std::time::Instant;

#[path = "common/smoke.rs"]
mod smoke;

/// Deterministic numbers in [0, 1) (SplitMix64).
fn uniform(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as f64 / u64::MAX as f64
}

fn main() {
    let mut seed = 17;
    // Anywhere in the box around the unit sphere (deep inside, near the
    // centre, every triangle is about equally near: the worst case of any
    // nearest-triangle search), and near the surface (|p| in [0.9, 1.1]:
    // boundary particles and collisions).
    // Smoke mode: 1,000 queries (the scan needs that many), spheres of 80
    // and 320 triangles, coarse sampling.
    let anywhere: Vec<Vector> = (0..smoke::pick(100_000, 1_000))
        .map(|_| Vector::from_fn(|_, _| 3.0 * uniform(&mut seed) - 1.5))
        .collect();
    let near: Vec<Vector> = anywhere
        .iter()
        .map(|p| p.normalize() * (0.9 + 0.2 * uniform(&mut seed)))
        .collect();
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    println!(
        "{:>9} {:>9} {:>16} {:>16} {:>16} {:>10}",
        "triangles",
        "build ms",
        "near, 1 thr us/q",
        "near, all us/q",
        "anywhere, 1 thr",
        "scan us/q"
    );
    for level in smoke::pick(vec![3, 5, 7], vec![1, 2]) {
        let mesh = TriMesh::icosphere(Vector::zeros(), 1.0, level);
        let start = Instant::now();
        let sdf = MeshSdf::new(&mesh).expect("closed");
        let build = start.elapsed().as_secs_f64() * 1e3;
        let per_query = |queries: &[Vector], pool: Option<&rayon::ThreadPool>| {
            let run = || queries.par_iter().map(|p| sdf.distance(p)).sum::<f64>();
            let start = Instant::now();
            std::hint::black_box(match pool {
                Some(pool) => pool.install(run),
                None => run(),
            });
            start.elapsed().as_secs_f64() * 1e6 / queries.len() as f64
        };
        let near_one = per_query(&near, Some(&single));
        let near_all = per_query(&near, None);
        let anywhere_one = per_query(&anywhere, Some(&single));
        // The scan: nearest vertex over every vertex, a lower bound on a
        // triangle scan's cost, on 1,000 queries.
        let start = Instant::now();
        let scanned: f64 = near[..1000]
            .iter()
            .map(|p| {
                mesh.vertices
                    .iter()
                    .map(|v| (v - p).norm_squared())
                    .fold(f64::INFINITY, f64::min)
            })
            .sum();
        std::hint::black_box(scanned);
        let scan = start.elapsed().as_secs_f64() * 1e6 / 1000.0;
        println!(
            "{:>9} {build:>9.1} {near_one:>16.3} {near_all:>16.3} {anywhere_one:>16.3} {scan:>10.3}",
            mesh.triangles.len()
        );
    }
    let sphere = TriMesh::icosphere(Vector::zeros(), 1.0, smoke::pick(5, 2));
    let sdf = MeshSdf::new(&sphere).expect("closed");
    for spacing in smoke::pick([0.02, 0.01], [0.2, 0.1]) {
        let start = Instant::now();
        let surface = sample_surface(&sphere, spacing).expect("surface");
        let surface_ms = start.elapsed().as_secs_f64() * 1e3;
        let start = Instant::now();
        let volume = sample_volume(&sdf, spacing).expect("volume");
        let volume_ms = start.elapsed().as_secs_f64() * 1e3;
        println!(
            "unit sphere, spacing {spacing}: {} surface points in {surface_ms:.0} ms, \
             {} volume points in {volume_ms:.0} ms (all cores)",
            surface.len(),
            volume.len()
        );
    }
}
