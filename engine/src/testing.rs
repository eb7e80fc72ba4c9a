//! Helpers shared by the engine's unit tests.

use crate::math::Real;

/// Deterministic pseudo-random numbers in [0, 1) (SplitMix64), so tests
/// are reproducible without a random-number crate.
pub fn uniform(seed: &mut u64) -> Real {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as Real / u64::MAX as Real
}
