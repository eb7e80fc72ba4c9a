//! Why a modal basis, parameter, constraint set or step is refused. Every
//! message names the input, its value and what to change; a refused call
//! leaves the system as it was.

use crate::math::{Brief, Real};

/// A modal input or step is invalid; nothing was changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModalError {
    /// The basis has no node or no mode.
    #[error(
        "the modal basis has {nodes} nodes and {modes} modes; it needs at least one of each \
         (pass the 3n x l mode shapes of a body with nodes, and keep at least one mode)"
    )]
    Empty {
        /// Node count n (rows / 3).
        nodes: usize,
        /// Mode count l.
        modes: usize,
    },
    /// The mode shapes do not have three rows per node.
    #[error("psi has {rows} rows; it needs 3 per node (x, y and z of each node's coefficient)")]
    NodeRows {
        /// Rows it has.
        rows: usize,
    },
    /// A matrix or vector has the wrong size.
    #[error("{what} is {got_rows} x {got_cols}; expected {expected_rows} x {expected_cols}")]
    Shape {
        /// Which input.
        what: &'static str,
        /// Rows it must have.
        expected_rows: usize,
        /// Columns it must have.
        expected_cols: usize,
        /// Rows it has.
        got_rows: usize,
        /// Columns it has.
        got_cols: usize,
    },
    /// An entry is NaN or infinite.
    #[error("{what}[{row}, {col}] = {value}; every entry must be finite")]
    NotFinite {
        /// Which input.
        what: &'static str,
        /// Its row.
        row: usize,
        /// Its column (0 for a vector).
        col: usize,
        /// The value.
        value: Real,
    },
    /// A stiffness eigenvalue is negative beyond rounding: the body would
    /// be unstable (Eq. 25 needs `Lambda >= 0`).
    #[error(
        "eigenvalue {index} = {}; eigenvalues must be >= 0 (accepted down to -{} as rounding \
         of a rigid mode); check the eigensolver's stiffness and mass matrices",
        Brief(*value), Brief(*tolerance)
    )]
    NegativeEigenvalue {
        /// Index of the mode.
        index: usize,
        /// Its eigenvalue.
        value: Real,
        /// The rounding allowance it fell below.
        tolerance: Real,
    },
    /// A damping or stabilisation coefficient is negative or not finite.
    #[error("{name} = {}; it must be finite and >= 0 (a negative value pumps energy in)", Brief(*value))]
    Coefficient {
        /// Which coefficient (`alpha`, `beta`, `eta`, `gamma`).
        name: &'static str,
        /// Its value.
        value: Real,
    },
    /// The time step is not a positive finite number.
    #[error("time step h = {}; it must be finite and > 0", Brief(*h))]
    TimeStep {
        /// The step.
        h: Real,
    },
    /// More constraint rows than the dense Schur solve is meant for.
    #[error(
        "{got} constraint rows; at most {max} are supported (Eq. 33 is solved densely); \
         drop constraints or fix the body with fewer, stiffer handles"
    )]
    TooManyConstraints {
        /// Rows given.
        got: usize,
        /// [`super::MAX_CONSTRAINTS`].
        max: usize,
    },
    /// The nodal loads are not one per node.
    #[error("{got} nodal loads for a basis of {expected} nodes; pass one load per node")]
    LoadCount {
        /// The node count.
        expected: usize,
        /// Loads given.
        got: usize,
    },
    /// A nodal load is NaN or infinite.
    #[error("the load on node {node} is not finite; every load component must be finite")]
    LoadNotFinite {
        /// The node.
        node: usize,
    },
    /// Setting targets while no constraint is set.
    #[error("no constraints are set; call set_constraints before setting their targets")]
    NoConstraints,
    /// The step overflowed (loads or targets too large for the state to
    /// stay finite); the state was kept.
    #[error(
        "the step made the modal state non-finite (loads or constraint targets too large); \
         the state was kept"
    )]
    Overflow,
}
