//! A spatial hash (tutorial Algorithms 1-2): particles bucketed by the
//! cell they fall in, cells mapped into a table of about 2n buckets by the
//! hash of Teschner et al. (2003). Unlike [`super::UniformGrid`] it needs
//! no bounding box, so it works on unbounded or growing domains, and its
//! memory is O(n) whatever the extent.

use super::CandidateSearch;
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// The cell size of a [`SpatialHash`], relative to the search radius r.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HashCell {
    /// Cells of size r; a query visits the 27 cells around the point.
    Radius,
    /// Cells of size 2r; a query visits the 8 cells around the cell corner
    /// nearest the point (the tutorial's trick): fewer buckets, more
    /// candidates per bucket.
    TwiceRadius,
}

/// Particles bucketed by hashed cell, built by a counting sort.
#[derive(Debug, Clone)]
pub struct SpatialHash {
    cell: HashCell,
    inv_cell: Real,
    /// `bucket_start[b]..bucket_start[b + 1]` indexes `sorted` for bucket
    /// `b`; `table_size + 1` entries.
    bucket_start: Vec<u32>,
    /// Particle indices ordered by bucket, stable within a bucket.
    sorted: Vec<u32>,
    /// Bucket of each particle.
    bucket_of: Vec<u32>,
    /// Scratch of the counting sort: next free slot per bucket.
    cursor: Vec<u32>,
}

/// Integer cell coordinates of a point. NaN maps to 0 and huge values
/// saturate (`as` semantics); the hash does not need them to be distinct.
#[inline]
fn cell_coords(p: &Vector, inv_cell: Real) -> [i64; 3] {
    [
        (p.x * inv_cell).floor() as i64,
        (p.y * inv_cell).floor() as i64,
        (p.z * inv_cell).floor() as i64,
    ]
}

/// Teschner et al. (2003): `(x p1 xor y p2 xor z p3) mod table_size`, on
/// wrapping 64-bit integers so negative coordinates hash as well.
#[inline]
fn hash(c: [i64; 3], table_size: u64) -> u32 {
    let h = (c[0] as u64).wrapping_mul(73_856_093)
        ^ (c[1] as u64).wrapping_mul(19_349_663)
        ^ (c[2] as u64).wrapping_mul(83_492_791);
    (h % table_size) as u32
}

/// The smallest prime at least `n` (trial division: n is about 2x the
/// particle count, so this costs microseconds).
fn next_prime(n: usize) -> usize {
    let is_prime = |k: usize| {
        k >= 2
            && (2..)
                .take_while(|d| d * d <= k)
                .all(|d| !k.is_multiple_of(d))
    };
    (n.max(2)..).find(|&k| is_prime(k)).unwrap_or(n)
}

impl SpatialHash {
    /// A hash for neighbour queries within `radius`, with cells of
    /// `radius` or `2 radius` (see [`HashCell`]).
    pub fn new(radius: Real, cell: HashCell) -> Self {
        let size = match cell {
            HashCell::Radius => radius,
            HashCell::TwiceRadius => 2.0 * radius,
        };
        Self {
            cell,
            inv_cell: 1.0 / size,
            bucket_start: Vec::new(),
            sorted: Vec::new(),
            bucket_of: Vec::new(),
            cursor: Vec::new(),
        }
    }

    /// Number of buckets: a prime about twice the particle count, so that
    /// most occupied cells get a bucket of their own (Algorithm 1).
    fn table_size(&self) -> usize {
        self.bucket_start.len().saturating_sub(1)
    }
}

impl CandidateSearch for SpatialHash {
    /// Algorithm 1: hash each particle's cell, then a counting sort into
    /// buckets (two passes, no per-bucket vectors). Buffers are reused;
    /// the table is resized only when the particle count changes, and
    /// allocates only when it grows past its largest size so far.
    fn rebuild(&mut self, positions: &[Vector]) {
        let n = positions.len();
        let size = next_prime(2 * n);
        if size != self.table_size() {
            self.bucket_start.resize(size + 1, 0);
            self.cursor.resize(size + 1, 0);
        }
        let (inv_cell, table) = (self.inv_cell, size as u64);
        self.bucket_of.resize(n, 0);
        self.bucket_of
            .par_iter_mut()
            .zip(positions.par_iter())
            .for_each(|(b, p)| *b = hash(cell_coords(p, inv_cell), table));
        self.bucket_start.fill(0);
        for &b in &self.bucket_of {
            self.bucket_start[b as usize + 1] += 1;
        }
        for b in 1..self.bucket_start.len() {
            self.bucket_start[b] += self.bucket_start[b - 1];
        }
        self.sorted.resize(n, 0);
        self.cursor.copy_from_slice(&self.bucket_start);
        for (i, &b) in self.bucket_of.iter().enumerate() {
            let slot = &mut self.cursor[b as usize];
            self.sorted[*slot as usize] = i as u32;
            *slot += 1;
        }
    }

    /// Algorithm 2: visit the buckets of the cells that can hold a point
    /// within r of `p`: the 27 cells around it for cells of size r, the 8
    /// cells around its nearest cell corner for cells of size 2r. A superset
    /// of the neighbours (the cells' other particles, and hash collisions);
    /// callers filter by distance.
    ///
    /// Two cells can hash to the same bucket, so the buckets are
    /// deduplicated before visiting: each particle is visited once.
    #[inline]
    fn for_each_candidate(&self, p: &Vector, mut visit: impl FnMut(u32)) {
        let table = self.table_size();
        if table == 0 {
            return;
        }
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        match self.cell {
            HashCell::Radius => {
                let c = cell_coords(p, self.inv_cell);
                for a in 0..3 {
                    lo[a] = c[a].saturating_sub(1);
                    hi[a] = c[a].saturating_add(1);
                }
            }
            HashCell::TwiceRadius => {
                // The ball [p - r, p + r] spans cells floor(p/2r - 1/2) and
                // floor(p/2r + 1/2): the two cells around the nearest
                // corner. A relative margin of 1e-12 guards the rounding of
                // p/2r +- 1/2 (a neighbour at just under r could otherwise
                // round into a third cell); it adds that third cell only for
                // points within the margin of a cell centre.
                for a in 0..3 {
                    let u = p[a] * self.inv_cell;
                    let eps = 1e-12 * (1.0 + u.abs());
                    lo[a] = (u - 0.5 - eps).floor() as i64;
                    hi[a] = (u + 0.5 + eps).floor() as i64;
                }
            }
        }
        let mut buckets = [0u32; 27];
        let mut count = 0;
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    if let Some(slot) = buckets.get_mut(count) {
                        *slot = hash([x, y, z], table as u64);
                        count += 1;
                    }
                }
            }
        }
        let buckets = &mut buckets[..count];
        buckets.sort_unstable();
        let mut previous = None;
        for &b in buckets.iter() {
            if previous == Some(b) {
                continue;
            }
            previous = Some(b);
            let start = self.bucket_start[b as usize] as usize;
            let end = self.bucket_start[b as usize + 1] as usize;
            for &j in &self.sorted[start..end] {
                visit(j);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn next_prime_finds_primes() {
        assert_eq!(next_prime(0), 2);
        assert_eq!(next_prime(14), 17);
        assert_eq!(next_prime(200_000), 200_003);
    }

    /// A point exactly at a cell centre: the margin adds the third cell
    /// per axis, and the query still visits each particle once.
    #[test]
    fn corner_query_visits_each_particle_once() {
        let positions = vec![Vector::repeat(1.0); 3];
        let mut hash = SpatialHash::new(0.5, HashCell::TwiceRadius);
        hash.rebuild(&positions);
        let mut seen = Vec::new();
        hash.for_each_candidate(&Vector::repeat(0.5), |j| seen.push(j));
        seen.sort_unstable();
        assert_eq!(seen, [0, 1, 2]);
    }
}
