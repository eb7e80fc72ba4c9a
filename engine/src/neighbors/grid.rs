//! A uniform grid over the simulation box, with cell size equal to the
//! support radius so that all neighbours of a particle lie in the 27 cells
//! around it. Built by a counting sort: O(n), no hashing in the hot loop.

use super::CandidateSearch;
use crate::math::{Brief, Real, Vector};
use rayon::prelude::*;

/// The grid would need more cells than [`UniformGrid::MAX_CELLS`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "the domain spans {} grid cells of size {} m, above the limit of {limit}; \
     shrink the domain or increase the support radius",
    Brief(*cells),
    Brief(*cell_size)
)]
pub struct GridError {
    /// Cells the box would need (product of the per-axis counts; a float
    /// so that a huge or NaN count is reported rather than overflowing).
    pub cells: f64,
    /// The requested cell size (m), usually the support radius.
    pub cell_size: Real,
    /// [`UniformGrid::MAX_CELLS`], the most cells a grid may have.
    pub limit: usize,
}

/// The geometry of the grid: where cell (0, 0, 0) starts, the cell sizes
/// and the cell counts. Particles outside the box are clamped into its
/// border cells, which keeps queries exact: clamping never separates two
/// cells by more than it separated the unclamped ones. Along a periodic
/// axis the cells tile the period exactly (so they are at least the
/// requested size) and the last cell neighbours the first.
#[derive(Debug, Clone, Copy)]
struct Lattice {
    origin: Vector,
    /// Inverse cell size per axis.
    inv_cell: Vector,
    dims: [usize; 3],
    periodic: [bool; 3],
}

impl Lattice {
    /// Integer cell coordinates of a point, clamped into the grid.
    #[inline]
    fn coords(&self, p: &Vector) -> [usize; 3] {
        let mut c = [0usize; 3];
        for axis in 0..3 {
            let f = ((p[axis] - self.origin[axis]) * self.inv_cell[axis]).floor();
            // NaN and negative values clamp to 0 (`as` saturates).
            c[axis] = (f.max(0.0) as usize).min(self.dims[axis] - 1);
        }
        c
    }

    #[inline]
    fn linear(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The cells next to coordinate `c` along `axis` (itself included):
    /// `lo..=hi` as one run, or, where a periodic axis wraps, up to three
    /// single-cell runs. Returns the runs and how many there are.
    #[inline]
    fn runs(&self, axis: usize, c: usize) -> ([(usize, usize); 3], usize) {
        let d = self.dims[axis];
        if self.periodic[axis] && (c == 0 || c + 1 == d) {
            let prev = (c + d - 1) % d;
            let next = (c + 1) % d;
            ([(prev, prev), (c, c), (next, next)], 3)
        } else {
            let lo = c.saturating_sub(1);
            let hi = (c + 1).min(d - 1);
            ([(lo, hi), (0, 0), (0, 0)], 1)
        }
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
    /// Fewest cells along a periodic axis: with fewer, a cell's left and
    /// right neighbours would be the same cell and be visited twice.
    pub const MIN_PERIODIC_CELLS: usize = 3;

    /// A grid covering `[min, max]` with cubic cells of `cell_size`.
    ///
    /// # Errors
    /// [`GridError`] when the box would need more than [`Self::MAX_CELLS`].
    pub fn new(min: Vector, max: Vector, cell_size: Real) -> Result<Self, GridError> {
        Self::with_periodic(min, max, cell_size, [false; 3])
    }

    /// A grid over `[min, max]` whose `periodic` axes wrap around. Along
    /// those axes the period is split into `floor(extent / cell_size)`
    /// cells, at least three so that a cell's neighbours are distinct
    /// (callers check [`Self::MIN_PERIODIC_CELLS`]).
    ///
    /// # Errors
    /// [`GridError`] when the box would need more than [`Self::MAX_CELLS`].
    pub fn with_periodic(
        min: Vector,
        max: Vector,
        cell_size: Real,
        periodic: [bool; 3],
    ) -> Result<Self, GridError> {
        let extent = max - min;
        let mut per_axis = Vector::zeros();
        for a in 0..3 {
            let cells = extent[a] / cell_size;
            per_axis[a] = if periodic[a] {
                cells.floor().max(Self::MIN_PERIODIC_CELLS as Real)
            } else {
                cells.ceil().max(1.0)
            };
        }
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
        let mut inv_cell = Vector::repeat(1.0 / cell_size);
        for a in 0..3 {
            if periodic[a] {
                inv_cell[a] = per_axis[a] / extent[a];
            }
        }
        let count = dims[0] * dims[1] * dims[2];
        Ok(Self {
            lattice: Lattice {
                origin: min,
                inv_cell,
                dims,
                periodic,
            },
            cell_start: vec![0; count + 1],
            sorted: Vec::new(),
            cell_of: Vec::new(),
            cursor: vec![0; count + 1],
        })
    }
}

impl UniformGrid {
    /// The corner where cell (0, 0, 0) starts.
    pub fn origin(&self) -> Vector {
        self.lattice.origin
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

    /// Calls `visit(j)` for every particle `j` in the 27 cells around `p`
    /// (wrapping around periodic axes). A superset of the neighbours within
    /// one cell size; callers filter by distance.
    #[inline]
    fn for_each_candidate(&self, p: &Vector, mut visit: impl FnMut(u32)) {
        let lattice = &self.lattice;
        let c = lattice.coords(p);
        let (xs, nx) = lattice.runs(0, c[0]);
        let (ys, ny) = lattice.runs(1, c[1]);
        let (zs, nz) = lattice.runs(2, c[2]);
        for &(z0, z1) in &zs[..nz] {
            for z in z0..=z1 {
                for &(y0, y1) in &ys[..ny] {
                    for y in y0..=y1 {
                        let row = lattice.linear([0, y, z]);
                        // Cells along x are contiguous: one run covers all
                        // three unless the x axis wraps here.
                        for &(x0, x1) in &xs[..nx] {
                            let start = self.cell_start[row + x0] as usize;
                            let end = self.cell_start[row + x1 + 1] as usize;
                            for &j in &self.sorted[start..end] {
                                visit(j);
                            }
                        }
                    }
                }
            }
        }
    }
}
