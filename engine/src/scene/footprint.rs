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
    /// Adds a fluid of `particles` with support `support` spacings.
    pub(super) fn add_fluid(&mut self, particles: Real, support: Real, dim: usize) {
        self.particles += particles;
        self.bytes += particles
            * (FLUID_BYTES_PER_PARTICLE + neighbours(support, dim) * FLUID_BYTES_PER_NEIGHBOUR);
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

#[cfg(test)]
mod tests {
    use super::*;

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
