//! Why a shell could not be built or solved. Every message says what to
//! change; a refused call changes nothing.

use crate::geometry::quadtree::{Point2, QuadtreeError};
use crate::linalg::eigen::EigenError;
use crate::math::{Brief, Real};

/// A shell input or solve was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShellError {
    /// A material property or solver parameter is out of range.
    #[error("shell `{what}` is {}; use {range}", Brief(*got))]
    Parameter {
        /// The parameter.
        what: &'static str,
        /// Its value.
        got: Real,
        /// What it may be.
        range: &'static str,
    },
    /// The constant basis has no derivatives to bend with.
    #[error("a shell needs the linear or quadratic basis; the constant basis has no curvature")]
    ConstantBasis,
    /// The quadtree refused the chart.
    #[error(transparent)]
    Quadtree(#[from] QuadtreeError),
    /// A point lies outside every cell of the chart.
    #[error("the point ({}, {}) lies outside the shell's chart", Brief(at[0]), Brief(at[1]))]
    Outside {
        /// The point.
        at: Point2,
    },
    /// The supports covering a point cannot carry the basis.
    #[error(
        "the point ({}, {}) lies under {supports} node supports, too few or too aligned for the \
         basis; raise eta (the support size) or use the linear basis",
        Brief(at[0]), Brief(at[1])
    )]
    Undersupported {
        /// The point.
        at: Point2,
        /// Supports covering it.
        supports: usize,
    },
    /// The reference surface has parallel tangents at a point.
    #[error(
        "the reference surface is degenerate at ({}, {}) (parallel tangents); check the chart's \
         map there, or refine",
        Brief(at[0]), Brief(at[1])
    )]
    Degenerate {
        /// The point.
        at: Point2,
    },
    /// The deformed surface folded flat at a point.
    #[error(
        "the shell folded flat at ({}, {}); reduce the load step or the load",
        Brief(at[0]), Brief(at[1])
    )]
    Folded {
        /// The point.
        at: Point2,
    },
    /// The projection of the reference surface onto the nodes failed.
    #[error(
        "the reference surface could not be fitted to the nodes (singular system); raise eta or \
         coarsen the resolution"
    )]
    Projection,
    /// The stiffness was not positive definite.
    #[error(
        "the shell's stiffness is singular: the supports leave a rigid motion free, or a load \
         step buckled it; add supports, or take smaller load steps"
    )]
    Singular,
    /// Too many nodes to index.
    #[error("{nodes} shell nodes are too many to index; coarsen the resolution")]
    TooLarge {
        /// Nodes.
        nodes: usize,
    },
    /// Newton's method did not reach the tolerance.
    #[error(
        "Newton's method stopped after {iterations} iterations at relative residual {}; take \
         more load steps or allow more iterations",
        Brief(*residual)
    )]
    NotConverged {
        /// Iterations taken in the last load step.
        iterations: usize,
        /// Residual over the load, at the end.
        residual: Real,
    },
    /// The eigensolver found no modes.
    #[error("the shell's vibration modes: {0}")]
    Modes(EigenError),
    /// The work was cancelled.
    #[error("the shell's work was cancelled")]
    Cancelled,
}

impl From<EigenError> for ShellError {
    fn from(e: EigenError) -> Self {
        match e {
            EigenError::Cancelled(_) => Self::Cancelled,
            other => Self::Modes(other),
        }
    }
}
