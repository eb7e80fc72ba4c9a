//! What a fracturing solid's scene chooses: when a crack starts, how it
//! cuts the particles' interactions, and how fast it may run.

use crate::math::{Brief, Real};
use serde::{Deserialize, Serialize};

/// When a particle starts a crack (tutorial Section 7.3; Pauly et al.
/// 2005, Section 4).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Threshold {
    /// Brittle: the largest principal Cauchy stress passes `stress`, Pa.
    Stress {
        /// Tensile strength, Pa.
        stress: Real,
    },
    /// Ductile: the accumulated plastic strain (Frobenius norm) passes
    /// `plastic_strain`; needs plasticity. The crack still opens normal
    /// to the largest principal stress.
    PlasticStrain {
        /// The plastic strain a particle tears at.
        plastic_strain: Real,
    },
}

/// How a crack cuts the weight between two particles on either side of it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Discontinuity {
    /// Belytschko et al. 1994: no interaction through a crack surface.
    /// Cheap and sharp, but a line of discontinuity runs on past the
    /// front (the tutorial's Figure 9, left).
    Visibility,
    /// Organ et al. 1996, tutorial Eq. 70: a crack between two particles
    /// lengthens their distance by `(d_s / (kappa spacing))^2` in the
    /// weight's argument, `d_s` the crossing's distance to the front, so
    /// the weight fades to zero behind the front instead of cutting off
    /// at it. Smaller `kappa` is more opaque.
    Transparency {
        /// Opacity scale of the crack surfaces, in particle spacings.
        kappa: Real,
    },
}

/// A scene's choice of [`Discontinuity`], without its parameter.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CrackCriterion {
    /// [`Discontinuity::Transparency`].
    #[default]
    Transparency,
    /// [`Discontinuity::Visibility`].
    Visibility,
}

impl Default for Discontinuity {
    fn default() -> Self {
        Self::Transparency {
            kappa: FractureParams::DEFAULT_KAPPA,
        }
    }
}

/// Fracture of an MLS solid.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FractureParams {
    /// When a particle starts a crack, and when a front keeps running.
    pub threshold: Threshold,
    /// How cracks cut interactions.
    #[serde(default)]
    pub discontinuity: Discontinuity,
    /// The farthest a front node advances in one step, in particle
    /// spacings (at most 1): a front that outran the particles it cuts
    /// would skip them.
    #[serde(default = "FractureParams::default_advance")]
    pub advance: Real,
    /// Most cracks the solid may hold; past it no crack starts (running
    /// ones still grow). Bounds the geometry with the particle count.
    #[serde(default = "FractureParams::default_max_cracks")]
    pub max_cracks: u32,
}

/// Why fracture parameters are refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FractureParamsError {
    /// A value out of its range.
    #[error("{what} must be {range}, got {got}")]
    OutOfRange {
        /// Which value.
        what: &'static str,
        /// Its valid range, in words.
        range: &'static str,
        /// The value given.
        got: Brief,
    },
    /// A ductile threshold on a solid without plastic flow.
    #[error(
        "a plastic_strain threshold needs plasticity; add a plasticity table or use a stress threshold"
    )]
    NeedsPlasticity,
    /// Plastic re-basing with fracture.
    #[error(
        "cracks live in the reference shape, which plasticity's rebase moves; drop plasticity.rebase on a fracturing solid"
    )]
    Rebase,
}

impl FractureParams {
    /// Default opacity scale of [`Discontinuity::Transparency`], in
    /// particle spacings.
    pub const DEFAULT_KAPPA: Real = 1.0;
    /// Default [`Self::advance`]: half a spacing per step.
    pub const DEFAULT_ADVANCE: Real = 0.5;
    /// Default [`Self::max_cracks`].
    pub const DEFAULT_MAX_CRACKS: u32 = 64;

    fn default_advance() -> Real {
        Self::DEFAULT_ADVANCE
    }

    fn default_max_cracks() -> u32 {
        Self::DEFAULT_MAX_CRACKS
    }

    /// A brittle solid of tensile strength `stress` with the defaults.
    pub fn brittle(stress: Real) -> Self {
        Self {
            threshold: Threshold::Stress { stress },
            discontinuity: Discontinuity::default(),
            advance: Self::DEFAULT_ADVANCE,
            max_cracks: Self::DEFAULT_MAX_CRACKS,
        }
    }

    /// Checks every value; `plastic` says whether the solid flows and
    /// `rebases` whether that flow re-bases its reference shape.
    ///
    /// # Errors
    /// [`FractureParamsError`] naming the value to change.
    pub fn validate(&self, plastic: bool, rebases: bool) -> Result<(), FractureParamsError> {
        let positive = |what, got: Real| {
            if got.is_finite() && got > 0.0 {
                Ok(())
            } else {
                Err(FractureParamsError::OutOfRange {
                    what,
                    range: "positive and finite",
                    got: Brief(got),
                })
            }
        };
        match self.threshold {
            Threshold::Stress { stress } => positive("stress", stress)?,
            Threshold::PlasticStrain { plastic_strain } => {
                positive("plastic_strain", plastic_strain)?;
                if !plastic {
                    return Err(FractureParamsError::NeedsPlasticity);
                }
            }
        }
        if let Discontinuity::Transparency { kappa } = self.discontinuity {
            positive("kappa", kappa)?;
        }
        if !(self.advance > 0.0 && self.advance <= 1.0) {
            return Err(FractureParamsError::OutOfRange {
                what: "advance",
                range: "in (0, 1] particle spacings",
                got: Brief(self.advance),
            });
        }
        if self.max_cracks == 0 {
            return Err(FractureParamsError::OutOfRange {
                what: "max_cracks",
                range: "at least 1",
                got: Brief(0.0),
            });
        }
        if rebases {
            return Err(FractureParamsError::Rebase);
        }
        Ok(())
    }
}
