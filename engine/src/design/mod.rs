//! The shape and motion optimiser (tutorial Section 8; Adams et al. 2008):
//! users pin and drag handles to deform a shape, and give keyframes,
//! velocities and obstacles to get a smooth deformable motion.
//!
//! - [`constraints`]: the named handle, velocity and obstacle constraints
//!   and their atomic edits;
//! - [`body`]: the sparse design particles and the MLS deformation field
//!   (Eq. 72-73), coupled by distance inside the shape ([`inside`]);
//! - [`shape`]: shape deformation, Eq. 74-78;
//! - [`temporal`], [`motion`]: the temporal MLS (Eq. 79-81) and motion
//!   design with adaptive temporal sampling (Eq. 82-85);
//! - `lsq`: the sparse Levenberg–Marquardt solver both use.

pub mod body;
pub mod constraints;
mod energy;
pub mod inside;
mod lsq;
pub mod motion;
pub mod params;
pub mod progress;
pub mod shape;
pub mod target;
pub mod temporal;

pub use body::{DesignBody, Embedding};
pub use constraints::{
    Constraint, ConstraintError, ConstraintKind, ConstraintSet, Context, Edit, Handle, Obstacle,
    Selection, Target, Velocity, Waypoint,
};
pub use motion::{Derivative, MotionSolution, blend, solve_motion, solve_motion_cancellable};
pub use params::{DesignParams, MotionParams, Quadrature, SolverParams, Weights};
pub use progress::{Energies, Observer, Progress, SolveInfo};
pub use shape::{ShapeSolution, solve_shape, solve_shape_cancellable};
pub use target::{DesignTarget, context};
pub use temporal::{TemporalBasis, TemporalError, TemporalWeight};

use crate::math::Real;

/// Runs `f` on a thread of rayon's pool. From a thread outside it (a
/// session's compute thread), every parallel loop of a solve would hand
/// its work to the pool and block until it is done; a drag frame runs
/// hundreds of small loops, each smaller than its hand-over. Within the
/// pool this is a plain call.
fn on_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| f())
}

/// Why a design could not be solved. Nothing the caller owns is changed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// A weight, solver setting or other design or motion parameter is
    /// unusable.
    #[error("design parameter `{field}`: {message}")]
    Parameter {
        /// Name of the parameter at fault.
        field: &'static str,
        /// Its value and what to change.
        message: String,
    },
    /// A named constraint is invalid, or unusable in this problem (it
    /// selects nothing usable, or a velocity lies outside the keyframes).
    #[error(transparent)]
    Constraint(#[from] ConstraintError),
    /// The constraints do not pose a problem of the kind asked for.
    #[error("{0}")]
    Problem(String),
    /// A material point has no design particle within the MLS support, so
    /// the deformation field (Eq. 72-73) is undefined there.
    #[error(
        "material point {point} at {position:?} sees no design particle within the support; \
         raise the support or lower the spacing"
    )]
    Unsupported {
        /// Index of the point among those embedded.
        point: usize,
        /// Its rest position, m.
        position: [Real; 3],
    },
    /// The high-resolution surface could not be embedded in the field: a
    /// vertex sees no particle or the mesh is invalid.
    #[error("embedded surface: {0}")]
    Surface(String),
    /// An energy term became NaN or infinite during the solve.
    #[error(
        "the {term} energy is not finite at iteration {iteration}; lower its weight or check \
         its constraints"
    )]
    Diverged {
        /// Name of the first non-finite term, as in [`Energies::named`].
        term: &'static str,
        /// Iterations so far over the run when it happened.
        iteration: u32,
        /// Every term's weighted energy at that iteration.
        energies: Energies,
    },
    /// The observer returned `Break`, or the solve's
    /// [`Cancel`](crate::Cancel) was raised; the solve stopped.
    #[error("cancelled at iteration {iteration}")]
    Cancelled {
        /// Iterations so far over the run when it stopped.
        iteration: u32,
    },
}

impl DesignError {
    pub(crate) fn constraint(name: &str, message: impl Into<String>) -> Self {
        Self::Constraint(ConstraintError {
            name: name.to_owned(),
            message: message.into(),
        })
    }
}

/// Checks the weights and solver settings, as both solvers do before
/// they start; public so that a host (and the fuzz targets) can check an
/// `Optimize` request's settings without a world.
///
/// # Errors
/// [`DesignError::Parameter`] naming the first setting out of range.
pub fn check_params(params: &DesignParams) -> Result<(), DesignError> {
    let invalid = |field, message: String| Err(DesignError::Parameter { field, message });
    for (name, w) in params.weights.named() {
        if !(w.is_finite() && w >= 0.0) {
            return invalid(
                name,
                format!("is {w}; weights must be finite and not negative"),
            );
        }
    }
    let s = &params.solver;
    if !(s.tolerance.is_finite() && s.tolerance > 0.0) {
        return invalid(
            "tolerance",
            format!("is {}; give a small positive number", s.tolerance),
        );
    }
    if !(s.linear_tolerance.is_finite() && s.linear_tolerance > 0.0 && s.linear_tolerance < 1.0) {
        return invalid(
            "linear_tolerance",
            format!("is {}; give a number in (0, 1)", s.linear_tolerance),
        );
    }
    if s.max_linear_iterations == 0 {
        return invalid("max_linear_iterations", "is 0; allow at least 1".into());
    }
    Ok(())
}
