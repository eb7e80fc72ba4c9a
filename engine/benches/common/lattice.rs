//! Jittered lattices the MLS and embedding benchmarks share: particle
//! layouts with realistic, slightly irregular neighbourhoods.

use nalgebra::Vector3;

type Vector = Vector3<f64>;

/// Deterministic numbers in [0, 1) (SplitMix64).
fn uniform(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as f64 / u64::MAX as f64
}

/// `count`^3 points of unit spacing, each jittered by up to a quarter
/// spacing per axis.
pub fn lattice(count: usize, seed: &mut u64) -> Vec<Vector> {
    let mut points = Vec::with_capacity(count * count * count);
    for i in 0..count {
        for j in 0..count {
            for k in 0..count {
                let mut p = Vector::new(i as f64, j as f64, k as f64);
                for a in 0..3 {
                    p[a] += (uniform(seed) - 0.5) * 0.5;
                }
                points.push(p);
            }
        }
    }
    points
}
