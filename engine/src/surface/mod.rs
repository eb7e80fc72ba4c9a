//! Surfaces meshed by marching cubes: an oriented point cloud's (in
//! [`reconstruct`], for shells from scans) and, here, fluid surfaces: the
//! iso-surface of the SPH colour field
//! `phi(x) = sum_j (m_j / rho_j) W(|x - x_j|, h)`, sampled on a regular grid
//! and meshed by marching cubes (Lorensen & Cline 1987), as the
//! Adams–Wicke tutorial's Section 6.5 describes.
//!
//! `phi` is a Shepard-like partition of unity: about 1 inside the fluid, 0
//! beyond a support radius of it, and 1/2 close to where the volumes the
//! particles represent end, half a spacing outside the centres of the
//! outermost particles. So the default iso value 1/2 wraps the fluid's
//! volume, whatever the particle count.

mod field;
mod marching_cubes;
pub mod reconstruct;

pub(crate) use field::NodeGrid;
pub(crate) use marching_cubes::extract;

use crate::approx::Kernel;
use crate::geometry::TriMesh;
use crate::math::{Real, Vector};

/// Why a surface extractor could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    /// The grid cell (m) given is not positive and finite.
    #[error("the grid cell must be a positive finite length, got {0}")]
    Cell(Real),
    /// The iso value given is not in (0, 1), where the colour field
    /// crosses from fluid to empty space.
    #[error("the iso value must lie strictly between 0 and 1, got {0}")]
    Iso(Real),
    /// The padded region holds more than [`SurfaceExtractor::MAX_NODES`]
    /// grid nodes at this cell size.
    #[error(
        "a surface grid of cell {cell} m over the domain needs {nodes:.3e} nodes, above the \
         limit of {limit}; increase the cell"
    )]
    TooManyNodes {
        /// Nodes the grid would need (a float, so a huge or NaN count is
        /// reported rather than overflowing).
        nodes: f64,
        /// The requested grid cell (m).
        cell: Real,
        /// [`SurfaceExtractor::MAX_NODES`].
        limit: usize,
    },
}

/// Meshes the colour-field surface of particles in a bounded region, on a
/// grid of nodes anchored at the region's corner, so that the grid of one
/// frame lines up with the next and a resting fluid gives the same mesh.
#[derive(Debug, Clone)]
pub struct SurfaceExtractor {
    kernel: Kernel,
    cell: Real,
    iso: Real,
    /// The region's corner and node counts, padded by a support radius and
    /// a cell so the field is 0 on the border of any grid inside it.
    origin: Vector,
    dims: [usize; 3],
}

impl SurfaceExtractor {
    /// Most nodes of the region's grid (16 Mi: 64 MiB of f32 values).
    pub const MAX_NODES: usize = 1 << 24;

    /// An extractor for particles inside `[min, max]`, with the colour
    /// field's `kernel` (the fluid's density kernel), nodes `cell` apart,
    /// and the surface at `phi = iso`.
    ///
    /// # Errors
    /// A non-positive or non-finite `cell`, `iso` outside (0, 1), or a
    /// region needing more than [`Self::MAX_NODES`] nodes.
    pub fn new(
        kernel: Kernel,
        cell: Real,
        iso: Real,
        min: Vector,
        max: Vector,
    ) -> Result<Self, SurfaceError> {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(SurfaceError::Cell(cell));
        }
        if !(iso > 0.0 && iso < 1.0) {
            return Err(SurfaceError::Iso(iso));
        }
        let pad = kernel.support() + cell;
        let origin = min.add_scalar(-pad);
        let per_axis = (max - min)
            .add_scalar(2.0 * pad)
            .map(|e| (e / cell).ceil() + 1.0);
        let nodes = per_axis.x * per_axis.y * per_axis.z;
        if nodes.is_nan() || nodes > Self::MAX_NODES as f64 {
            return Err(SurfaceError::TooManyNodes {
                nodes,
                cell,
                limit: Self::MAX_NODES,
            });
        }
        Ok(Self {
            kernel,
            cell,
            iso,
            origin,
            dims: [0, 1, 2].map(|a| per_axis[a] as usize),
        })
    }

    /// Spacing of the grid nodes (m).
    pub fn cell(&self) -> Real {
        self.cell
    }

    /// The colour-field value `phi` the surface is drawn at, in (0, 1).
    pub fn iso(&self) -> Real {
        self.iso
    }

    /// The closed, outward-oriented surface `phi = iso` of the particles at
    /// `positions` with volumes `m_j / rho_j`. The field is sampled only on
    /// the part of the region's grid that the particles' supports reach.
    /// Particles outside the region are clipped with it. Runs in parallel.
    ///
    /// # Panics
    /// When `volumes` is shorter than `positions` (a programming error).
    pub fn extract(&self, positions: &[Vector], volumes: &[Real]) -> TriMesh {
        assert!(
            volumes.len() >= positions.len(),
            "one volume per particle: {} volumes for {} particles",
            volumes.len(),
            positions.len()
        );
        let (mut lo, mut hi) = (
            Vector::repeat(Real::INFINITY),
            Vector::repeat(-Real::INFINITY),
        );
        for p in positions.iter().filter(|p| p.iter().all(|c| c.is_finite())) {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        if lo.x > hi.x {
            return TriMesh::default();
        }
        // Node ranges covering the particles and their supports, plus one
        // cell so the border nodes are outside, clipped to the region.
        let pad = self.kernel.support() + self.cell;
        let mut first = [0usize; 3];
        let mut dims = [0usize; 3];
        for a in 0..3 {
            let last = self.dims[a] as Real - 1.0;
            let n0 = ((lo[a] - pad - self.origin[a]) / self.cell)
                .floor()
                .clamp(0.0, last);
            let n1 = ((hi[a] + pad - self.origin[a]) / self.cell)
                .ceil()
                .clamp(0.0, last);
            first[a] = n0 as usize;
            dims[a] = (n1 - n0) as usize + 1;
        }
        let origin = self.origin + Vector::from(first.map(|f| f as Real)) * self.cell;
        let grid = field::colour_field(positions, volumes, &self.kernel, origin, self.cell, dims);
        marching_cubes::extract(&grid, self.iso as f32)
    }
}

#[cfg(test)]
mod tests;
