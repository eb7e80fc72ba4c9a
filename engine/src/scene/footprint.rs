//! What a scene will cost in memory, estimated from its spec before
//! anything is allocated, so that a host can refuse a scene it cannot
//! hold instead of finding out by running out of memory.
//!
//! The estimate is per particle: a fixed part (the state, the per-step
//! buffers) and a part per neighbour (neighbour lists, cached pair
//! gradients, and for implicit solids the Newton matrix blocks), with the
//! neighbour count of a full support ball on the lattice. The constants
//! are measured and rounded up: resident growth after building and two
//! steps, per particle at the default support (34.5 neighbours in 3D),
//! was 474 B for WCSPH and 855 B for DFSPH (102k particles), 3.2 kB for an
//! explicit and 3.8 kB for an implicit CG solid (27k and 8k); the
//! `engine/tests/footprint_*.rs` tests check, each in a fresh process,
//! that the estimate stays above the measurement and within three times
//! it. An implicit solid with `linear_solver = "cholesky"` also holds its
//! factor, whose fill-in the estimate does not model.

use crate::math::Real;
use std::f64::consts::PI;

/// Bytes per fluid particle besides its neighbours.
const FLUID_BYTES_PER_PARTICLE: Real = 250.0;
/// Bytes per fluid neighbour pair (list entry; DFSPH's cached gradient).
const FLUID_BYTES_PER_NEIGHBOUR: Real = 22.0;
/// Bytes per solid particle besides its neighbours.
const SOLID_BYTES_PER_PARTICLE: Real = 1000.0;
/// Bytes per solid neighbour pair (MLS weights, shape-function gradients).
const SOLID_BYTES_PER_NEIGHBOUR: Real = 80.0;
/// Extra bytes per neighbour pair of an implicit solid (Newton matrix
/// blocks and the CG vectors over them).
const IMPLICIT_BYTES_PER_NEIGHBOUR: Real = 20.0;

/// Bytes held per byte of a mesh file: the file itself in the session's
/// and the world's scene, and the parsed mesh (three f64 coordinates per
/// vertex, a triangle's indices, the distance field's tree), which a
/// binary PLY of f32 coordinates about doubles. An upper estimate by
/// counting, not a measurement: mesh bodies are few and bounded by the
/// host's mesh size limit.
const BYTES_PER_MESH_BYTE: Real = 6.0;

/// The particles and bytes a scene's world will hold.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Footprint {
    /// Particles of every system.
    pub particles: Real,
    /// Estimated resident bytes of the built world.
    pub bytes: Real,
}

impl Footprint {
    /// Adds a fluid of `particles` on a lattice, with support `support`
    /// spacings.
    pub(crate) fn add_fluid(&mut self, particles: Real, support: Real, dim: usize) {
        self.add_fluid_pairs(particles, particles * neighbours(support, dim));
    }

    /// Adds a fluid of `particles` that make `pairs` neighbour pairs (a
    /// restored layout's, `pairs_in_cells`).
    pub fn add_fluid_pairs(&mut self, particles: Real, pairs: Real) {
        self.particles += particles;
        self.bytes +=
            particles * FLUID_BYTES_PER_PARTICLE + pairs.max(0.0) * FLUID_BYTES_PER_NEIGHBOUR;
    }

    /// Adds a mesh shape whose file has `bytes` bytes.
    pub(super) fn add_mesh(&mut self, bytes: usize) {
        self.bytes += bytes as Real * BYTES_PER_MESH_BYTE;
    }

    /// Adds a modal solid, already built: its nodes and the bytes it
    /// holds by its own count ([`crate::efg::ModalSolid::bytes`]).
    pub(super) fn add_modal_solid(&mut self, solid: &crate::efg::ModalSolid) {
        self.particles += solid.len() as Real;
        self.bytes += solid.bytes() as Real;
    }

    /// Adds a shell, already built: its nodes and the bytes it holds by
    /// count ([`super::PreparedShell::bytes`]).
    pub(super) fn add_shell(&mut self, nodes: usize, bytes: Real) {
        self.particles += nodes as Real;
        self.bytes += bytes;
    }

    /// Adds a solid of `particles` with support `support` spacings.
    pub(super) fn add_solid(&mut self, particles: Real, support: Real, dim: usize, implicit: bool) {
        let per_neighbour = SOLID_BYTES_PER_NEIGHBOUR
            + if implicit {
                IMPLICIT_BYTES_PER_NEIGHBOUR
            } else {
                0.0
            };
        self.particles += particles;
        self.bytes +=
            particles * (SOLID_BYTES_PER_PARTICLE + neighbours(support, dim) * per_neighbour);
    }
}

/// Neighbours of a particle on a lattice of unit spacing within `support`:
/// the support disc or ball, plus the particle's own cell.
fn neighbours(support: Real, dim: usize) -> Real {
    let ball = if dim == 2 {
        PI * support * support
    } else {
        4.0 / 3.0 * PI * support.powi(3)
    };
    ball + 1.0
}

/// Neighbour pairs (each particle's own included, as in [`neighbours`])
/// of particles binned into cells of unit spacing, `(cell, count)`: each
/// particle counts the particles of the cells within `support` spacings,
/// scaled by the share of that block of cells the support ball covers.
/// On a lattice this is [`neighbours`] per particle; a pile counts the
/// square of its size. One pass over the occupied cells, each visiting
/// `(2 ceil(support) + 1)^dim` cells.
pub(super) fn pairs_in_cells(
    cells: impl Iterator<Item = ([i64; 3], usize)>,
    support: Real,
    dim: usize,
) -> Real {
    let cells: std::collections::HashMap<[i64; 3], usize> = cells.collect();
    // A support of a few spacings, or the estimate is meaningless anyway.
    let reach = support.ceil().clamp(1.0, 8.0) as i64;
    let width = (2 * reach + 1) as Real;
    let share = (neighbours(support, dim) - 1.0) / width.powi(dim as i32);
    let z_reach = if dim == 2 { 0 } else { reach };
    let mut pairs = 0.0;
    for (cell, &count) in &cells {
        let mut around = 0usize;
        for dz in -z_reach..=z_reach {
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let other = [cell[0] + dx, cell[1] + dy, cell[2] + dz];
                    around += cells.get(&other).copied().unwrap_or(0);
                }
            }
        }
        pairs += count as Real * (around as Real * share + 1.0);
    }
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_pairs_match_the_lattice_and_grow_with_a_pile() {
        // A 20^3 lattice, one particle per cell: interior particles see
        // the support ball, the edges fewer.
        let lattice: Vec<([i64; 3], usize)> = (0..8000)
            .map(|i| ([i % 20, (i / 20) % 20, i / 400], 1))
            .collect();
        let pairs = pairs_in_cells(lattice.into_iter(), 2.0, 3);
        let full = 8000.0 * neighbours(2.0, 3);
        assert!(
            pairs <= full && pairs > 0.5 * full,
            "{pairs} pairs against {full} for a full ball each"
        );
        // 8000 particles piled in one cell: every one sees all others.
        let pile = pairs_in_cells(std::iter::once(([0, 0, 0], 8000)), 2.0, 3);
        assert!(pile > 8000.0 * 8000.0 * 0.2, "{pile} pairs for a pile");
    }

    #[test]
    fn neighbour_counts_are_those_of_the_support_ball() {
        // h = 2 spacings: 4 pi + 1 in 2D, 32 pi / 3 + 1 in 3D.
        assert!((neighbours(2.0, 2) - (4.0 * PI + 1.0)).abs() < 1e-12);
        assert!((neighbours(2.0, 3) - (32.0 * PI / 3.0 + 1.0)).abs() < 1e-12);
    }

    #[test]
    fn bytes_grow_with_particles_support_and_implicitness() {
        let mut small = Footprint::default();
        small.add_fluid(1000.0, 2.0, 3);
        let mut twice = Footprint::default();
        twice.add_fluid(2000.0, 2.0, 3);
        assert_eq!(twice.bytes, 2.0 * small.bytes);
        let mut wide = Footprint::default();
        wide.add_fluid(1000.0, 3.0, 3);
        assert!(wide.bytes > small.bytes);
        let (mut explicit, mut implicit) = (Footprint::default(), Footprint::default());
        explicit.add_solid(1000.0, 2.0, 3, false);
        implicit.add_solid(1000.0, 2.0, 3, true);
        assert!(implicit.bytes > explicit.bytes);
        assert_eq!(implicit.particles, 1000.0);
    }
}
