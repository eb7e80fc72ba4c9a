//! Z-order (Morton) keys of grid cells. Storing particles in the order of
//! their cells along this space-filling curve keeps particles that are
//! close in space close in memory, in all three axes at once, so the
//! neighbour gathers of every pass hit the cache. Row-major order keeps
//! only x-neighbours together: z-neighbours end up a whole slab apart.

use crate::math::{Real, Vector};
use rayon::prelude::*;

/// The order that sorts `positions` by the Z-order key of their cells (a
/// lattice of `cell` sized cubes from `origin`; points below the origin
/// share the first cell): `order[k]` is the index of the particle that
/// goes to slot `k`. Ties keep the current order, so the result is
/// deterministic.
pub fn zorder(positions: &[Vector], origin: &Vector, cell: Real) -> Vec<u32> {
    let inv = 1.0 / cell;
    let mut keyed: Vec<(u64, u32)> = positions
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            // Negative and NaN offsets saturate to cell 0.
            let c = [0, 1, 2].map(|a| (((p[a] - origin[a]) * inv).floor().max(0.0)) as usize);
            (morton(c), i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// Spreads the low 21 bits of `v` to every third bit.
#[inline]
fn spread(v: u64) -> u64 {
    let mut x = v & 0x1f_ffff;
    x = (x | (x << 32)) & 0x1f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x1f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// The Morton key of cell `c`: the bits of x, y and z interleaved
/// (21 bits per axis, beyond any grid [`super::UniformGrid`] allows).
#[inline]
pub fn morton(c: [usize; 3]) -> u64 {
    spread(c[0] as u64) | (spread(c[1] as u64) << 1) | (spread(c[2] as u64) << 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The key interleaves bits: x in bit 0, y in bit 1, z in bit 2, and
    /// so on up the 21 bits of every axis.
    #[test]
    fn keys_interleave_bits() {
        assert_eq!(morton([1, 0, 0]), 0b001);
        assert_eq!(morton([0, 1, 0]), 0b010);
        assert_eq!(morton([0, 0, 1]), 0b100);
        assert_eq!(morton([3, 0, 0]), 0b001_001);
        assert_eq!(morton([0b11, 0b10, 0b01]), 0b011_101);
        let top = 1 << 20;
        assert_eq!(morton([top, top, top]), 0b111 << 60);
    }

    /// Particles come out sorted by cell key, each exactly once.
    #[test]
    fn order_is_a_permutation_sorted_by_cell() {
        let positions: Vec<Vector> = (0..200)
            .map(|i| {
                let t = i as Real * 0.37;
                Vector::new(t.sin().abs(), (2.0 * t).cos().abs(), (t * 0.1).fract())
            })
            .collect();
        let order = zorder(&positions, &Vector::zeros(), 0.1);
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..200).collect::<Vec<u32>>());
        let key = |i: u32| {
            let p = positions[i as usize];
            morton([0, 1, 2].map(|a| (p[a] / 0.1).floor() as usize))
        };
        assert!(order.windows(2).all(|w| key(w[0]) <= key(w[1])));
    }

    /// A 2x2x2 block of cells is contiguous along the curve: the eight
    /// keys of every aligned block are consecutive.
    #[test]
    fn aligned_blocks_are_contiguous() {
        for base in [[0, 0, 0], [2, 4, 6], [8, 2, 14]] {
            let mut keys: Vec<u64> = (0..8)
                .map(|k| {
                    morton([
                        base[0] + (k & 1),
                        base[1] + (k >> 1 & 1),
                        base[2] + (k >> 2),
                    ])
                })
                .collect();
            keys.sort_unstable();
            assert!(keys.windows(2).all(|w| w[1] == w[0] + 1), "{keys:?}");
            assert_eq!(keys[0] % 8, 0);
        }
    }
}
