//! Neighbour search: which particles lie within the support radius of each
//! particle. Three interchangeable candidate searches feed one flat (CSR)
//! list that solver passes read without locks:
//!
//! - [`UniformGrid`]: a bounded grid with cell size r and a counting sort,
//!   the default for the bounded, fairly uniform fluids of the scenes;
//! - [`SpatialHash`]: the same buckets hashed into a table of about 2n
//!   entries (tutorial Algorithms 1-2), for unbounded domains;
//! - [`KdTree`]: a median-split tree (tutorial Algorithms 3-4), whose
//!   leaves adapt to strongly varying density.

mod grid;
mod hash;
mod kdtree;
mod list;
mod periodic;
mod zorder;

pub use grid::{GridError, UniformGrid};
pub use hash::{HashCell, SpatialHash};
pub use kdtree::KdTree;
pub use list::NeighborList;
pub use periodic::Periodic;
pub use zorder::{morton, zorder};

use crate::math::Vector;

/// A spatial index that, after [`rebuild`](Self::rebuild), enumerates for
/// a query point a superset of the particles within the search radius the
/// index was built for. [`NeighborList::build`] filters the candidates by
/// distance, so an implementation trades exactness for speed freely; it
/// must never miss a neighbour nor visit one twice.
///
/// `Sync` because [`NeighborList::build`] queries it from rayon workers.
pub trait CandidateSearch: Sync {
    /// Re-indexes `positions`; reuses buffers from earlier rebuilds.
    fn rebuild(&mut self, positions: &[Vector]);

    /// Calls `visit(j)` once for each candidate `j` near `p`: every `j`
    /// within the radius the index was built for, and possibly others.
    fn for_each_candidate(&self, p: &Vector, visit: impl FnMut(u32));
}

#[cfg(test)]
mod tests;
