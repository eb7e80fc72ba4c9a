//! Flat (CSR) neighbour lists: `offsets` and one `indices` array, built once
//! per sub-step and read-only while forces are computed.

use super::{CandidateSearch, Periodic};
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// Particles per parallel work item while filling the lists.
const CHUNK: usize = 256;

/// For each particle `i`, the particles `j` (itself included) with
/// `|x_i - x_j| < radius` (through the nearest periodic image where axes
/// are periodic), in the order the search visits them.
#[derive(Debug, Clone, Default)]
pub struct NeighborList {
    offsets: Vec<u32>,
    indices: Vec<u32>,
    /// Periodic axes of the last build, applied to pair separations.
    periodic: Option<Periodic>,
    /// Per work item: neighbour counts and indices of its particles, kept
    /// between builds so that rebuilding does not allocate.
    chunks: Vec<(Vec<u32>, Vec<u32>)>,
}

impl NeighborList {
    /// Rebuilds the lists for `positions` from a search already rebuilt
    /// with the same positions (and for a radius of at least `radius`), in
    /// one pass over the candidates, keeping those closer than `radius`.
    /// Runs in parallel, one gather per particle; the result does not
    /// depend on the thread count.
    pub fn build<S: CandidateSearch>(&mut self, search: &S, positions: &[Vector], radius: Real) {
        self.build_periodic(search, positions, radius, None);
    }

    /// [`Self::build`] in a box with `periodic` axes: distances are taken
    /// to the nearest periodic image, and [`Self::pairs`] yields those
    /// images' separations. The search must wrap around the same axes.
    pub fn build_periodic<S: CandidateSearch>(
        &mut self,
        search: &S,
        positions: &[Vector],
        radius: Real,
        periodic: Option<Periodic>,
    ) {
        self.build_between(search, positions, positions, radius, periodic);
    }

    /// Rebuilds the lists of points `queries` against another set,
    /// `targets`, that `search` was rebuilt with: `of(i)` then lists the
    /// targets within `radius` of query `i` (rigid boundary samples near
    /// each fluid particle, say), through the nearest image along
    /// `periodic` axes. Parallel like [`Self::build`].
    pub fn build_between<S: CandidateSearch>(
        &mut self,
        search: &S,
        queries: &[Vector],
        targets: &[Vector],
        radius: Real,
        periodic: Option<Periodic>,
    ) {
        self.periodic = periodic;
        let n = queries.len();
        let r2 = radius * radius;
        self.chunks.resize_with(n.div_ceil(CHUNK), Default::default);
        self.chunks
            .par_iter_mut()
            .enumerate()
            .for_each(|(c, (counts, found))| {
                counts.clear();
                found.clear();
                for &xi in &queries[c * CHUNK..((c + 1) * CHUNK).min(n)] {
                    let before = found.len();
                    search.for_each_candidate(&xi, |j| {
                        let d = targets[j as usize] - xi;
                        let d = periodic.map_or(d, |p| p.image(d));
                        if d.norm_squared() < r2 {
                            found.push(j);
                        }
                    });
                    counts.push((found.len() - before) as u32);
                }
            });
        self.offsets.clear();
        self.offsets.push(0);
        self.indices.clear();
        let mut total = 0;
        for (counts, found) in &self.chunks {
            for &k in counts {
                total += k;
                self.offsets.push(total);
            }
            self.indices.extend_from_slice(found);
        }
    }

    /// Keeps only the pairs `(i, j)` for which `keep(i, j)` holds, in
    /// their order: a list built at the largest of several radii narrowed
    /// to each pair's own (particles with support radii of their own).
    pub fn retain(&mut self, keep: impl Fn(usize, u32) -> bool) {
        let mut write = 0;
        let mut start = 0;
        for i in 0..self.len() {
            let end = self.offsets[i + 1] as usize;
            for k in start..end {
                let j = self.indices[k];
                if keep(i, j) {
                    self.indices[write] = j;
                    write += 1;
                }
            }
            start = end;
            self.offsets[i + 1] = write as u32;
        }
        self.indices.truncate(write);
    }

    /// Neighbours of particle `i`, itself included.
    #[inline]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.indices[self.range(i)]
    }

    /// Where the neighbours of particle `i` lie in the flat list of all
    /// pairs (particle after particle): per-pair data kept in an array
    /// aligned with that list is read with the same range.
    #[inline]
    pub fn range(&self, i: usize) -> std::ops::Range<usize> {
        self.offsets[i] as usize..self.offsets[i + 1] as usize
    }

    /// Neighbours `j` of particle `i` (itself included) with the
    /// separation `x_i - x_j`, taken to the nearest periodic image where
    /// the list was built with periodic axes. `positions` must be those
    /// the list was built from.
    #[inline]
    pub fn pairs<'a>(
        &'a self,
        i: usize,
        positions: &'a [Vector],
    ) -> impl Iterator<Item = (usize, Vector)> + 'a {
        let xi = positions[i];
        let periodic = self.periodic;
        self.of(i).iter().map(move |&j| {
            let j = j as usize;
            let d = xi - positions[j];
            (j, periodic.map_or(d, |p| p.image(d)))
        })
    }

    /// Number of particles the lists were built for.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Whether the lists were built for no particles.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Total number of (ordered) neighbour pairs, self-pairs included.
    pub fn pair_count(&self) -> usize {
        self.indices.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neighbors::UniformGrid;
    use crate::testing::uniform;

    fn brute_force(positions: &[Vector], i: usize, radius: Real) -> Vec<u32> {
        let mut v: Vec<u32> = (0..positions.len())
            .filter(|&j| (positions[j] - positions[i]).norm_squared() < radius * radius)
            .map(|j| j as u32)
            .collect();
        v.sort_unstable();
        v
    }

    /// The grid query must find exactly the particles a brute-force scan
    /// finds, including particles outside the box (clamped into border
    /// cells) and clusters denser than one per cell.
    #[test]
    fn grid_neighbours_match_brute_force() {
        let mut seed = 7;
        let min = Vector::new(0.0, 0.0, 0.0);
        let max = Vector::new(1.0, 0.5, 0.7);
        let radius = 0.11;
        let mut positions: Vec<Vector> = (0..1500)
            .map(|_| {
                // Some particles up to 0.2 outside the box on every side.
                Vector::new(
                    -0.2 + 1.4 * uniform(&mut seed),
                    -0.2 + 0.9 * uniform(&mut seed),
                    -0.2 + 1.1 * uniform(&mut seed),
                )
            })
            .collect();
        // A dense clump and two coincident particles.
        for k in 0..50 {
            positions.push(Vector::new(0.5, 0.25, 0.35) + Vector::repeat(k as Real * 1e-4));
        }
        positions.push(Vector::new(0.3, 0.3, 0.3));
        positions.push(Vector::new(0.3, 0.3, 0.3));

        let mut grid = UniformGrid::new(min, max, radius).expect("small grid");
        grid.rebuild(&positions);
        let mut list = NeighborList::default();
        list.build(&grid, &positions, radius);
        assert_eq!(list.len(), positions.len());
        for i in 0..positions.len() {
            let mut found = list.of(i).to_vec();
            found.sort_unstable();
            assert_eq!(found, brute_force(&positions, i, radius), "particle {i}");
        }
    }

    /// Lists between two sets (fluid particles against boundary samples)
    /// match a brute-force scan of the targets.
    #[test]
    fn cross_lists_match_brute_force() {
        let mut seed = 5;
        let radius = 0.1;
        let mut cloud = |n: usize| -> Vec<Vector> {
            (0..n)
                .map(|_| Vector::new(uniform(&mut seed), uniform(&mut seed), uniform(&mut seed)))
                .collect()
        };
        let (queries, targets) = (cloud(700), cloud(300));
        let mut grid =
            UniformGrid::new(Vector::zeros(), Vector::repeat(1.0), radius).expect("grid");
        grid.rebuild(&targets);
        let mut list = NeighborList::default();
        list.build_between(&grid, &queries, &targets, radius, None);
        assert_eq!(list.len(), queries.len());
        for (i, q) in queries.iter().enumerate() {
            let mut found = list.of(i).to_vec();
            found.sort_unstable();
            let expected: Vec<u32> = (0..targets.len() as u32)
                .filter(|&j| (targets[j as usize] - q).norm() < radius)
                .collect();
            assert_eq!(found, expected, "query {i}");
        }
    }

    #[test]
    fn grid_refuses_absurd_cell_counts() {
        let err = UniformGrid::new(Vector::zeros(), Vector::repeat(1000.0), 0.001)
            .expect_err("1e18 cells");
        assert!(err.cells > UniformGrid::MAX_CELLS as f64);
    }
}
