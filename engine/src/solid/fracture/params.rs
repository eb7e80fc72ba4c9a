//! What a fracturing solid's scene chooses: when a crack starts, how it
//! cuts the particles' interactions, and how fast it may run.

use crate::math::{Brief, Real, Vector};
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
    /// Brittle with a fracture toughness: the point method of the theory
    /// of critical distances (Taylor 2007; Whitney & Nuismer 1974). A
    /// crack starts where the largest principal stress passes `stress`
    /// (the strength `sigma_0`), as [`Self::Stress`]; a front runs when
    /// that stress, sampled the critical distance
    /// `r_c = K_Ic^2 / (2 pi sigma_0^2)` ahead of it, passes `stress`. On
    /// the near-tip field `sigma = K_I / sqrt(2 pi r)` that is `K_I >=
    /// K_Ic`, Irwin's form of Griffith's criterion: with surface energy
    /// `gamma`, `K_Ic = sqrt(2 E gamma)` (plane stress), and a through
    /// crack of half-length `a` under remote tension runs at
    /// `sigma_c = sqrt(2 E gamma / (pi a))`, whatever the particle
    /// spacing, as long as the spacing resolves `r_c`.
    Toughness {
        /// Tensile strength `sigma_0`, Pa.
        stress: Real,
        /// Mode I fracture toughness `K_Ic`, Pa m^(1/2).
        toughness: Real,
    },
    /// Ductile: the accumulated plastic strain (Frobenius norm) passes
    /// `plastic_strain`; needs plasticity. The crack still opens normal
    /// to the largest principal stress.
    PlasticStrain {
        /// The plastic strain a particle tears at.
        plastic_strain: Real,
    },
}

impl Threshold {
    /// The point method's critical distance `K_Ic^2 / (2 pi sigma_0^2)`,
    /// m: how far ahead of a front [`Self::Toughness`] samples the
    /// stress. `None` for the other thresholds, which sample at the
    /// front.
    pub fn critical_distance(&self) -> Option<Real> {
        match *self {
            Self::Toughness { stress, toughness } => {
                Some(toughness * toughness / (std::f64::consts::TAU * stress * stress))
            }
            Self::Stress { .. } | Self::PlasticStrain { .. } => None,
        }
    }
}

/// A crack the solid is built with, in reference coordinates: a flaw or
/// a machined notch. In 2D a segment of half-length `radius` through
/// `center` normal to `normal` (in the plane); in 3D a disc (a
/// penny-shaped crack). Parts of it outside the body are inert: their
/// front stops at the first update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Notch {
    /// Its centre, m.
    pub center: Vector,
    /// The normal of its plane (any length but zero).
    pub normal: Vector,
    /// Half-length (2D) or radius (3D), m.
    pub radius: Real,
}

impl Notch {
    /// Checks a notch of a `dim`-dimensional solid: finite, a normal that
    /// is not zero (in the plane in 2D), a positive radius.
    ///
    /// # Errors
    /// [`FractureParamsError::Notch`] saying what to change.
    pub fn validate(&self, dim: usize) -> Result<(), FractureParamsError> {
        let bad = |why: &str| Err(FractureParamsError::Notch(why.to_owned()));
        if !(self
            .center
            .iter()
            .chain(self.normal.iter())
            .all(|x| x.is_finite()))
        {
            return bad("its centre and normal must be finite");
        }
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return bad("its radius must be positive and finite");
        }
        let normal = if dim == 2 {
            if self.normal.z != 0.0 || self.center.z != 0.0 {
                return bad("in 2D its centre and normal lie in the plane: set their z to 0");
            }
            self.normal.xy().norm()
        } else {
            self.normal.norm()
        };
        if normal < 1e-12 {
            return bad("its normal must not be zero");
        }
        Ok(())
    }
}

/// Whether `notches` fit a solid of `particles` particles and particle
/// `spacing` that already holds `held` cracks of `held_vertices`
/// vertices: no more cracks than `max_cracks`, no more crack vertices than
/// the solid's bound ([`VERTICES_PER_PARTICLE`] each and an allowance).
/// What a scene checks before the build, and [`Body::notch`] again.
///
/// [`VERTICES_PER_PARTICLE`]: super::VERTICES_PER_PARTICLE
/// [`Body::notch`]: crate::solid::Body::notch
///
/// # Errors
/// [`FractureParamsError::Notch`] saying which bound and what to change.
pub fn check_room(
    notches: &[Notch],
    (held, held_vertices): (usize, usize),
    max_cracks: u32,
    (dim, spacing, particles): (usize, Real, usize),
) -> Result<(), FractureParamsError> {
    let cracks = held + notches.len();
    if cracks > max_cracks as usize {
        return Err(FractureParamsError::Notch(format!(
            "{cracks} cracks with the notches, past max_cracks = {max_cracks}; raise max_cracks \
             or drop notches"
        )));
    }
    let vertices = held_vertices
        + notches
            .iter()
            .map(|n| super::Crack::notch_vertices(dim, n, spacing))
            .sum::<usize>();
    let limit = super::VERTICES_PER_PARTICLE * particles + 1024;
    if vertices > limit {
        return Err(FractureParamsError::Notch(format!(
            "the notches need {vertices} crack vertices, past the {limit} a solid of \
             {particles} particles may hold; make them smaller"
        )));
    }
    Ok(())
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
    /// Branching: a running front whose stress passes this many times
    /// the threshold splits in two, a new crack leaving its tip
    /// [`FractureParams::BRANCH_ANGLE`] to one side of its heading
    /// (turned about the front's tangent; in 2D about `z`) while it turns
    /// as far to the other; none never branches.
    #[serde(default)]
    pub branching: Option<Real>,
    /// Adaptive resampling near cracks (tutorial Eq. 71); none keeps the
    /// particles the solid was built with.
    #[serde(default)]
    pub resample: Option<Resampling>,
    /// The grid cell on which a 3D solid in pieces cuts each piece's
    /// closed surface, in particle spacings: a smaller cell keeps more of
    /// the embedded surface's detail and bevels the pieces' edges less,
    /// for nodes (and rebuild time) growing as its inverse cube.
    #[serde(default = "FractureParams::default_surface_cell")]
    pub surface_cell: Real,
}

/// Adaptive resampling (tutorial Section 7.3, Eq. 71, after Pauly et al.
/// 2005): at the start of a step a particle whose neighbours the cracks
/// hid (its transparency-weighted count `Q_i` under `min(q_min, N_i)`,
/// `N_i` the neighbours its support holds uncut) is split into itself and
/// an even number of new particles around it on its side of every crack,
/// `ceil` of the shortfall, its volume and mass shared evenly and every
/// part's support radius shrunk by `(parts)^(1/dim)` so the density
/// stays; never below `min_radius_ratio` times the solid's radius.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Resampling {
    /// `Q_min`, the neighbour count a particle is kept at (Pauly et al.
    /// use 10).
    #[serde(default = "Resampling::default_q_min")]
    pub q_min: Real,
    /// The smallest support radius a split may leave, as a fraction of
    /// the solid's support radius, in (0, 1): what stops runaway
    /// splitting beside a crack.
    #[serde(default = "Resampling::default_min_radius_ratio")]
    pub min_radius_ratio: Real,
    /// The most particles the solid may grow to; none: twice those it
    /// was built with. Growth past it ends the step with
    /// `ResampleError::ParticleLimit`.
    #[serde(default)]
    pub max_particles: Option<u32>,
}

impl Resampling {
    /// Default [`Self::q_min`] (Pauly et al. 2005).
    pub const DEFAULT_Q_MIN: Real = 10.0;
    /// Default [`Self::min_radius_ratio`]: two generations of splits in
    /// 2D, three in 3D.
    pub const DEFAULT_MIN_RADIUS_RATIO: Real = 0.5;
    /// Most particles one particle may be split into in one step.
    pub const MAX_PARTS: usize = 65;

    fn default_q_min() -> Real {
        Self::DEFAULT_Q_MIN
    }

    fn default_min_radius_ratio() -> Real {
        Self::DEFAULT_MIN_RADIUS_RATIO
    }

    /// The defaults: `Q_min` 10, half the support radius, twice the
    /// particles.
    pub fn new() -> Self {
        Self {
            q_min: Self::DEFAULT_Q_MIN,
            min_radius_ratio: Self::DEFAULT_MIN_RADIUS_RATIO,
            max_particles: None,
        }
    }

    /// The most particles a solid built with `built` may hold.
    pub fn capacity(&self, built: usize) -> usize {
        self.max_particles
            .map_or(built.saturating_mul(2), |m| m as usize)
    }

    fn validate(&self) -> Result<(), FractureParamsError> {
        if !(self.q_min.is_finite() && (1.0..=(Self::MAX_PARTS as Real)).contains(&self.q_min)) {
            return Err(FractureParamsError::OutOfRange {
                what: "resample.q_min",
                range: "between 1 and 65 neighbours",
                got: Brief(self.q_min),
            });
        }
        if !(self.min_radius_ratio > 0.0 && self.min_radius_ratio < 1.0) {
            return Err(FractureParamsError::OutOfRange {
                what: "resample.min_radius_ratio",
                range: "in (0, 1), a fraction of the support radius",
                got: Brief(self.min_radius_ratio),
            });
        }
        Ok(())
    }
}

impl Default for Resampling {
    fn default() -> Self {
        Self::new()
    }
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
    /// A notch out of its ranges.
    #[error("a notch: {0}")]
    Notch(String),
    /// A toughness whose critical distance the particles cannot resolve.
    #[error(
        "toughness and stress give a critical distance K_Ic^2 / (2 pi stress^2) of {distance} m, \
         under the particle spacing {spacing} m, so no particle could sample the stress there; \
         raise the toughness, lower the stress or refine the spacing"
    )]
    Unresolved {
        /// The critical distance.
        distance: Brief,
        /// The spacing.
        spacing: Brief,
    },
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
    /// Default [`Self::surface_cell`]: half a spacing, finer than the
    /// particles that carry the motion.
    pub const DEFAULT_SURFACE_CELL: Real = 0.5;
    /// The range [`Self::surface_cell`] may take, in spacings: below a
    /// quarter a solid's grid holds over 64 nodes a particle, and a cell
    /// past a spacing leaves slivers of surface at a box's corners (one
    /// showed at a whole spacing).
    pub const SURFACE_CELL_RANGE: (Real, Real) = (0.25, 1.0);
    /// Half the angle between the two arms of a branch, rad (15
    /// degrees): a model choice, not a material's.
    pub const BRANCH_ANGLE: Real = 15.0 * std::f64::consts::PI / 180.0;

    fn default_advance() -> Real {
        Self::DEFAULT_ADVANCE
    }

    fn default_max_cracks() -> u32 {
        Self::DEFAULT_MAX_CRACKS
    }

    fn default_surface_cell() -> Real {
        Self::DEFAULT_SURFACE_CELL
    }

    /// A brittle solid of tensile strength `stress` with the defaults.
    pub fn brittle(stress: Real) -> Self {
        Self {
            threshold: Threshold::Stress { stress },
            discontinuity: Discontinuity::default(),
            advance: Self::DEFAULT_ADVANCE,
            max_cracks: Self::DEFAULT_MAX_CRACKS,
            branching: None,
            resample: None,
            surface_cell: Self::DEFAULT_SURFACE_CELL,
        }
    }

    /// Checks every value for a solid of particle `spacing` (the same
    /// rules in 2D and 3D); `plastic` says whether the solid flows and `rebases`
    /// whether that flow re-bases its reference shape.
    ///
    /// # Errors
    /// [`FractureParamsError`] naming the value to change.
    pub fn validate(
        &self,
        spacing: Real,
        plastic: bool,
        rebases: bool,
    ) -> Result<(), FractureParamsError> {
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
            Threshold::Toughness { stress, toughness } => {
                positive("stress", stress)?;
                positive("toughness", toughness)?;
                let distance = self.threshold.critical_distance().unwrap_or(0.0);
                if distance.is_nan() || distance < spacing {
                    return Err(FractureParamsError::Unresolved {
                        distance: Brief(distance),
                        spacing: Brief(spacing),
                    });
                }
            }
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
        if let Some(branching) = self.branching
            && !(branching.is_finite() && branching >= 1.0)
        {
            return Err(FractureParamsError::OutOfRange {
                what: "branching",
                range: "at least 1 (times the threshold) and finite",
                got: Brief(branching),
            });
        }
        if self.max_cracks == 0 {
            return Err(FractureParamsError::OutOfRange {
                what: "max_cracks",
                range: "at least 1",
                got: Brief(0.0),
            });
        }
        let (lo, hi) = Self::SURFACE_CELL_RANGE;
        if !(lo..=hi).contains(&self.surface_cell) {
            return Err(FractureParamsError::OutOfRange {
                what: "surface_cell",
                range: "in [0.25, 1] particle spacings",
                got: Brief(self.surface_cell),
            });
        }
        if rebases {
            return Err(FractureParamsError::Rebase);
        }
        if let Some(resample) = &self.resample {
            resample.validate()?;
        }
        Ok(())
    }
}
