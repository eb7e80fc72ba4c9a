//! Why a scene is rejected, and the range checks that say so: every
//! error names the offending field and what to change.

use super::Aabb;
use crate::math::{Brief, Real};

/// Why a scene was rejected. Every variant names the offending field and
/// says what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// A field is out of its allowed range.
    #[error("{field}: {message}")]
    Invalid {
        /// The field's path in the scene (`systems[0].spacing`).
        field: String,
        /// What is wrong and what to change.
        message: String,
    },
    /// The scene would create more particles than the host allows.
    #[error(
        "the scene creates {count} particles, above this host's limit of {limit}; \
         increase `spacing` or shrink the fluid blocks"
    )]
    TooManyParticles {
        /// Particles the scene would create.
        count: u64,
        /// The host's limit ([`super::BuildOptions::max_particles`]).
        limit: u64,
    },
    /// A solid's lattice (or a modal solid's octree) would hold more
    /// points than the engine takes: a resource limit, like
    /// [`Self::TooManyParticles`], not a bad value. The message names the
    /// key to raise, the last part of `field` (`spacing`, `cell`).
    #[error(
        "{field}: fills the shape's bounding box with about {points} points (lattice points \
         or octree nodes), more than the limit of {limit}; raise `{}`",
        key_of(.field)
    )]
    TooFine {
        /// The resolution at fault (a solid's `spacing`, a modal solid's
        /// `cell`).
        field: String,
        /// Lattice points the spacing asks for.
        points: u64,
        /// Most lattice points the engine samples.
        limit: u64,
    },
    /// The scene file could not be read or parsed.
    #[error("{0}")]
    Parse(String),
    /// A system's memory, estimated before it is built, does not fit what
    /// the host's [`super::BuildOptions::budget`] has left: a resource
    /// limit, refused before the memory is taken.
    #[error("{field}: {message}")]
    OverBudget {
        /// The system.
        field: String,
        /// The estimate, what the host has left and what to change.
        message: String,
    },
    /// The check was stopped through [`super::BuildOptions::cancel`].
    #[error("the scene's check was cancelled before it finished")]
    Cancelled,
}

/// The key a field path ends with: `cell` of `systems[0].cell`.
fn key_of(field: &str) -> &str {
    field.rsplit('.').next().unwrap_or(field)
}

impl SceneError {
    pub(super) fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            message: message.into(),
        }
    }

    /// Appends why the range is what it is.
    pub(super) fn with_hint(self, hint: &str) -> Self {
        match self {
            Self::Invalid { field, message } => Self::Invalid {
                field,
                message: format!("{message} ({hint})"),
            },
            other => other,
        }
    }
}

/// Checks that `value` is finite and inside `[lo, hi]` (`hi` may be infinite).
pub(super) fn check_range(field: &str, value: Real, lo: Real, hi: Real) -> Result<(), SceneError> {
    if !value.is_finite() {
        return Err(SceneError::invalid(
            field,
            format!("must be a finite number, got {}", Brief(value)),
        ));
    }
    if value < lo || value > hi {
        let range = if hi.is_infinite() {
            format!(">= {}", Brief(lo))
        } else {
            format!("in [{}, {}]", Brief(lo), Brief(hi))
        };
        return Err(SceneError::invalid(
            field,
            format!("must be {range}, got {}", Brief(value)),
        ));
    }
    Ok(())
}

pub(super) fn check_positive(field: &str, value: Real) -> Result<(), SceneError> {
    check_range(field, value, 0.0, Real::INFINITY)?;
    if value == 0.0 {
        return Err(SceneError::invalid(field, "must be > 0, got 0"));
    }
    Ok(())
}

pub(super) fn check_vector(field: &str, v: [Real; 3]) -> Result<(), SceneError> {
    for (axis, value) in ["x", "y", "z"].iter().zip(v) {
        if !value.is_finite() {
            return Err(SceneError::invalid(
                format!("{field}.{axis}"),
                format!("must be a finite number, got {}", Brief(value)),
            ));
        }
    }
    Ok(())
}

/// Checks a box in the first `dim` axes (in 2D its z extent is ignored).
pub(super) fn check_box(field: &str, b: &Aabb, dim: usize) -> Result<(), SceneError> {
    check_vector(&format!("{field}.min"), b.min)?;
    check_vector(&format!("{field}.max"), b.max)?;
    for (a, axis) in ["x", "y", "z"].iter().enumerate().take(dim) {
        if b.max[a] <= b.min[a] {
            return Err(SceneError::invalid(
                field,
                format!(
                    "is empty: max.{axis} ({}) must exceed min.{axis} ({})",
                    b.max[a], b.min[a]
                ),
            ));
        }
    }
    Ok(())
}
