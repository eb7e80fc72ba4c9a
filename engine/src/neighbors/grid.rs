//! A uniform grid over the simulation box, with cell size equal to the
//! support radius so that all neighbours of a particle lie in the 27 cells
//! around it. Built by a counting sort: O(n), no hashing in the hot loop.

use super::CandidateSearch;
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// The grid would need more cells than [`UniformGrid::MAX_CELLS`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the domain spans {cells} grid cells of size {cell_size} m, above the limit of {limit}; \
     shrink the domain or increase the support radius"
)]
pub struct GridError {
    pub cells: f64,
    pub cell_size: Real,
    pub limit: usize,
}

/// The geometry of the grid: where cell (0, 0, 0) starts, the cell size
/// and the cell counts. Particles outside the box are clamped into its
/// border cells, which keeps queries exact: clamping never separates two
/// cells by more than it separated the unclamped ones.
#[derive(Debug, Clone, Copy)]
struct Lattice {
    origin: Vector,
    inv_cell: Real,
    dims: [usize; 3],
}

impl Lattice {
    /// Integer cell coordinates of a point, clamped into the grid.
    #[inline]
    fn coords(&self, p: &Vector) -> [usize; 3] {
        let mut c = [0usize; 3];
        for axis in 0..3 {
            let f = ((p[axis] - self.origin[axis]) * self.inv_cell).floor();
            // NaN and negative values clamp to 0 (`as` saturates).
            c[axis] = (f.max(0.0) as usize).min(self.dims[axis] - 1);
        }
        c
    }

    #[inline]
    fn linear(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }
}

/// Particles bucketed by grid cell.
#[derive(Debug, Clone)]
pub struct UniformGrid {
    lattice: Lattice,
    /// `cell_start[c]..cell_start[c + 1]` indexes `sorted` for cell `c`.
    cell_start: Vec<u32>,
    /// Particle indices ordered by cell, stable within a cell.
    sorted: Vec<u32>,
    /// Linear cell index of each particle.
    cell_of: Vec<u32>,
    /// Scratch of the counting sort: next free slot per cell.
    cursor: Vec<u32>,
}

impl UniformGrid {
    /// Upper bound on the number of cells (16 Mi cells, 64 MiB of starts).
    pub const MAX_CELLS: usize = 1 << 24;

    /// A grid covering `[min, max]` with cubic cells of `cell_size`.
    ///
    /// # Errors
    /// [`GridError`] when the box would need more than [`Self::MAX_CELLS`].
    pub fn new(min: Vector, max: Vector, cell_size: Real) -> Result<Self, GridError> {
        let extent = max - min;
        let per_axis = extent.map(|e| (e / cell_size).ceil().max(1.0));
        let cells = per_axis.x * per_axis.y * per_axis.z;
        if cells.is_nan() || cells > Self::MAX_CELLS as f64 {
            return Err(GridError {
                cells,
                cell_size,
                limit: Self::MAX_CELLS,
            });
        }
        let dims = [
            per_axis.x as usize,
            per_axis.y as usize,
            per_axis.z as usize,
        ];
        let count = dims[0] * dims[1] * dims[2];
        Ok(Self {
            lattice: Lattice {
                origin: min,
                inv_cell: 1.0 / cell_size,
                dims,
            },
            cell_start: vec![0; count + 1],
            sorted: Vec::new(),
            cell_of: Vec::new(),
            cursor: vec![0; count + 1],
        })
    }
}

impl CandidateSearch for UniformGrid {
    /// Buckets `positions` by cell (counting sort). Reuses its buffers.
    fn rebuild(&mut self, positions: &[Vector]) {
        let lattice = self.lattice;
        self.cell_of.resize(positions.len(), 0);
        self.cell_of
            .par_iter_mut()
            .zip(positions.par_iter())
            .for_each(|(cell, p)| *cell = lattice.linear(lattice.coords(p)) as u32);
        self.cell_start.fill(0);
        for &c in &self.cell_of {
            self.cell_start[c as usize + 1] += 1;
        }
        for c in 1..self.cell_start.len() {
            self.cell_start[c] += self.cell_start[c - 1];
        }
        self.sorted.resize(positions.len(), 0);
        self.cursor.copy_from_slice(&self.cell_start);
        for (i, &c) in self.cell_of.iter().enumerate() {
            let slot = &mut self.cursor[c as usize];
            self.sorted[*slot as usize] = i as u32;
            *slot += 1;
        }
    }

    /// Calls `visit(j)` for every particle `j` in the 27 cells around `p`.
    /// A superset of the neighbours within one cell size; callers filter by
    /// distance.
    #[inline]
    fn for_each_candidate(&self, p: &Vector, mut visit: impl FnMut(u32)) {
        let lattice = &self.lattice;
        let c = lattice.coords(p);
        let lo = |a: usize| c[a].saturating_sub(1);
        let hi = |a: usize| (c[a] + 1).min(lattice.dims[a] - 1);
        for z in lo(2)..=hi(2) {
            for y in lo(1)..=hi(1) {
                let row = lattice.linear([0, y, z]);
                let start = self.cell_start[row + lo(0)] as usize;
                let end = self.cell_start[row + hi(0) + 1] as usize;
                // Cells along x are contiguous: one run covers all three.
                for &j in &self.sorted[start..end] {
                    visit(j);
                }
            }
        }
    }
}
