//! Neighbour search: which particles lie within the support radius of each
//! particle. The uniform grid with a counting sort is the default; the
//! result is a flat (CSR) list that solver passes read without locks.

mod grid;
mod list;

pub use grid::{GridError, UniformGrid};
pub use list::NeighborList;
