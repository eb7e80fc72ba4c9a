//! Helpers shared by the engine's unit tests.

use crate::math::{Real, Vector};
use std::f64::consts::PI;

/// Deterministic pseudo-random numbers in [0, 1) (SplitMix64), so tests
/// are reproducible without a random-number crate.
pub fn uniform(seed: &mut u64) -> Real {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as Real / u64::MAX as Real
}

/// `n` points on the unit sphere in a Fibonacci spiral: evenly spread,
/// none repeated.
pub fn fibonacci_sphere(n: usize) -> Vec<Vector> {
    let golden = PI * (3.0 - 5.0_f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2 * i + 1) as Real / n as Real;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as Real;
            Vector::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// A random unit vector, uniform on the sphere (rejection from the cube).
pub fn random_unit(seed: &mut u64) -> Vector {
    loop {
        let v =
            Vector::new(uniform(seed), uniform(seed), uniform(seed)) * 2.0 - Vector::repeat(1.0);
        let n2 = v.norm_squared();
        if n2 > 1e-4 && n2 <= 1.0 {
            return v / n2.sqrt();
        }
    }
}

/// Each normal turned by a random angle of up to `max_degrees` about a
/// random axis perpendicular to it: the noise of a scanned cloud.
pub fn perturb_normals(normals: &[Vector], max_degrees: Real, seed: &mut u64) -> Vec<Vector> {
    normals
        .iter()
        .map(|n| {
            let axis = n.cross(&random_unit(seed)).normalize();
            let angle = uniform(seed) * max_degrees.to_radians();
            n * angle.cos() + axis * angle.sin()
        })
        .collect()
}
