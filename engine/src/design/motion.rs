//! Motion design (tutorial Section 8.2). Being written.

use super::body::DesignBody;
use super::constraints::ConstraintSet;
use super::progress::{Observer, SolveInfo};
use super::temporal::TemporalBasis;
use super::{DesignError, DesignParams, MotionParams};
use crate::math::{Real, Vector};

/// A solved motion: the design particles' displacements at each frame,
/// blended in time by the temporal MLS (Eq. 81).
#[derive(Debug, Clone)]
pub struct MotionSolution {
    basis: TemporalBasis,
    frames: Vec<Vec<Vector>>,
    pub info: SolveInfo,
}

impl MotionSolution {
    /// Frame times, s (keyframes and inserted frames).
    pub fn times(&self) -> &[Real] {
        self.basis.times()
    }

    /// `u_(i, t_j)`: per frame, one displacement per design particle.
    pub fn frames(&self) -> &[Vec<Vector>] {
        &self.frames
    }

    /// First and last frame times.
    pub fn span(&self) -> (Real, Real) {
        let t = self.basis.times();
        (t[0], t[t.len() - 1])
    }

    /// The design particles' displacements at time `t` (Eq. 80).
    ///
    /// # Errors
    /// [`DesignError::Parameter`] for a time outside [`Self::span`].
    pub fn displacements_at(&self, t: Real) -> Result<Vec<Vector>, DesignError> {
        let mut weights = Vec::new();
        self.basis
            .shape_functions(t, &mut weights)
            .map_err(|e| DesignError::Parameter {
                field: "time",
                message: e.to_string(),
            })?;
        let n = self.frames[0].len();
        let mut u = vec![Vector::zeros(); n];
        for w in &weights {
            for (u, f) in u.iter_mut().zip(&self.frames[w.frame]) {
                *u += f * w.value;
            }
        }
        Ok(u)
    }
}

/// Solves the motion the timed handles (keyframes), velocities and
/// obstacles of `constraints` pose on `body`.
///
/// # Errors
/// As [`super::solve_shape`]; [`DesignError::Problem`] with fewer than
/// two keyframe times.
pub fn solve_motion(
    body: &DesignBody,
    constraints: &ConstraintSet,
    params: &DesignParams,
    motion: &MotionParams,
    observer: &mut Observer<'_>,
) -> Result<MotionSolution, DesignError> {
    let _ = (body, constraints, params, motion, observer);
    Err(DesignError::Problem(
        "motion design is being written".into(),
    ))
}
