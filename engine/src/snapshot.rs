//! What every system's snapshot shares: the error of a state that does
//! not fit the system it is restored into, and the checks behind it. A
//! snapshot may come from anyone (a file, a client): each system checks
//! all of it before changing anything. The states themselves live with
//! their systems (`fluid/snapshot.rs`, `solid/snapshot.rs`) and the
//! world's (`world/state.rs`); their encoding is the wire crate's.

use crate::math::{Real, Vector};

/// Why a snapshot does not fit the system it is restored into; nothing
/// was changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SnapshotError {
    /// A per-particle or per-body array has the wrong length.
    #[error("{what} holds {got} values where {expected} were expected")]
    Length {
        /// Which array.
        what: &'static str,
        /// What the system needs.
        expected: usize,
        /// What the snapshot holds.
        got: usize,
    },
    /// More particles than the scene builds.
    #[error("{got} particles where the scene builds at most {limit}")]
    TooMany {
        /// What the snapshot holds.
        got: usize,
        /// What the scene builds.
        limit: usize,
    },
    /// A value is not finite, or out of its range.
    #[error("{what} of entry {index} is invalid ({value:e})")]
    Invalid {
        /// Which quantity.
        what: &'static str,
        /// Its entry.
        index: usize,
        /// The offending value.
        value: Real,
    },
    /// A shape crowded far past the one its system was built with.
    #[error(
        "the reference shape's particles are crowded: up to {bound} neighbour pairs where \
         the solid allows {limit} (a shape piled onto a few points)"
    )]
    Crowded {
        /// The shape's pairs, bounded from its cells.
        bound: u64,
        /// What the solid allows.
        limit: u64,
    },
    /// The particle ids are not distinct ids below `next_id`.
    #[error(
        "the particle ids are not a permutation of distinct ids below next_id ({next_id}), the ids \
         the fluid has given"
    )]
    Ids {
        /// The id the next particle would get.
        next_id: u32,
    },
}

/// The first entry of `values` that is not finite, as an error.
pub(crate) fn check_finite(what: &'static str, values: &[Real]) -> Result<(), SnapshotError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(SnapshotError::Invalid {
            what,
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

/// [`check_finite`] over vectors, and their count.
pub(crate) fn check_vectors(
    what: &'static str,
    values: &[Vector],
    expected: usize,
) -> Result<(), SnapshotError> {
    check_length(what, values.len(), expected)?;
    match values.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        Some(index) => Err(SnapshotError::Invalid {
            what,
            index,
            value: values[index].norm(),
        }),
        None => Ok(()),
    }
}

/// A length error unless `got == expected`.
pub(crate) fn check_length(
    what: &'static str,
    got: usize,
    expected: usize,
) -> Result<(), SnapshotError> {
    if got == expected {
        Ok(())
    } else {
        Err(SnapshotError::Length {
            what,
            expected,
            got,
        })
    }
}
