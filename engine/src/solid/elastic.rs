//! An MLS elastic solid as the world steps it: its [`Body`] (the state)
//! and the integrator that advances it (the buffers its steps reuse).

use super::body::{Body, SolidError};
use super::contact::{Obstacles, Penalty};
use super::fracture::{FractureError, FractureStep};
use super::integrate::{Integrator, SolidStep};
use super::material::Hyperelastic;
use super::params::SolidParams;
use super::resampling::{Resample, ResampleError};
use crate::cancel::{Cancel, Cancelled};
use crate::math::{Real, Vector};
use crate::stats::StageTimer;
use nalgebra::Matrix3;
use std::ops::{Deref, DerefMut};

/// A body sampled by particles whose elastic forces come from the MLS
/// displacement gradient in material coordinates (tutorial Section 7.1),
/// with its time integrator.
///
/// It reads as its body: `solid.positions`, `solid.len()`, `solid.save(..)`
/// are the [`Body`]'s, so that only stepping goes through the integrator.
#[derive(Debug, Clone)]
pub struct ElasticSolid {
    pub(super) body: Body,
    pub(super) integrator: Integrator,
}

impl ElasticSolid {
    /// A solid at rest shape `rest` with initial `velocities` and the
    /// particles flagged in `fixed` anchored, colliding with `obstacles`,
    /// advanced by the integrator `params.integrator` names.
    ///
    /// # Errors
    /// [`SolidError`] when the inputs disagree in length, are empty, or
    /// the MLS parameters are invalid.
    pub fn new(
        params: SolidParams,
        rest: Vec<Vector>,
        velocities: Vec<Vector>,
        fixed: Vec<bool>,
        obstacles: Obstacles,
    ) -> Result<Self, SolidError> {
        let integrator = Integrator::new(&params.integrator);
        Ok(Self {
            body: Body::new(params, rest, velocities, fixed, obstacles)?,
            integrator,
        })
    }

    /// Advances by `dt` under `gravity`, in at most `max_substeps`
    /// explicit sub-steps.
    pub fn step(&mut self, dt: Real, gravity: &Vector, max_substeps: u32) -> SolidStep {
        // A flag no one else holds is never raised.
        self.step_cancellable(
            dt,
            gravity,
            max_substeps,
            &Cancel::new(),
            &mut StageTimer::default(),
        )
        .unwrap_or_default()
    }

    /// [`Self::step`], stopping at the next sub-step, Newton or CG
    /// iteration once `cancel` is raised, each pass counted in `timer`
    /// (the `Solid*` stages).
    ///
    /// # Errors
    /// [`Cancelled`]; the state may then be part-way through the step:
    /// put back one [`Body::save`] kept before it.
    pub fn step_cancellable(
        &mut self,
        dt: Real,
        gravity: &Vector,
        max_substeps: u32,
        cancel: &Cancel,
        timer: &mut StageTimer,
    ) -> Result<SolidStep, Cancelled> {
        self.integrator
            .step(&mut self.body, dt, gravity, max_substeps, cancel, timer)
    }

    /// Advances the solid's cracks after a step (tutorial Section 7.3;
    /// `fracture/`): fronts run, cracks start, the pairs they cut are
    /// reweighed and the fragments kept. Nothing for a solid without
    /// fracture. [`Self::step`] and [`Self::step_cancellable`] move the
    /// particles only, so a caller steps and then calls this.
    ///
    /// # Errors
    /// [`FractureError`] when the cracks outgrew their bound (checked
    /// once they grew): put back a [`Body::save`] kept before the step,
    /// as the world does for any failed step.
    pub fn fracture_step(&mut self) -> Result<FractureStep, FractureError> {
        let states = self.integrator.states();
        self.body.fracture_step(states)
    }

    /// Splits the particles cracks left short of neighbours (tutorial Eq.
    /// 71; `resampling.rs`), between steps: new particles are appended,
    /// so every particle keeps its index. Nothing for a solid that does
    /// not resample. The integrator's buffers start again for the new
    /// count (its one carried decision, `auto`'s switch to Cholesky,
    /// kept).
    ///
    /// # Errors
    /// [`ResampleError::ParticleLimit`] past [`Body::capacity`].
    pub fn resample(&mut self) -> Result<Resample, ResampleError> {
        let done = self.body.resample()?;
        if done.added > 0 {
            let escalated = self.integrator.escalated();
            self.integrator = Integrator::new(&self.body.params.integrator);
            self.integrator.set_escalated(escalated);
        }
        Ok(done)
    }

    /// Mechanical energy under `gravity` after a step of `dt`: kinetic,
    /// stored (elastic, volume, hourglass, and the implicit contact
    /// penalty's, which depends on the step) and gravitational
    /// `-sum m g . x`, J (per metre of depth in 2D).
    pub fn mechanical_energy(&self, gravity: &Vector, dt: Real) -> Real {
        let body = &self.body;
        let p = &body.params;
        let contact = match (
            &self.integrator,
            Penalty::new(&body.obstacles, p.dim, p.spacing, p.young, dt),
        ) {
            (Integrator::Implicit(_), Some(penalty)) => body
                .positions
                .iter()
                .zip(&body.masses)
                .zip(&body.fixed)
                .filter(|(_, fixed)| !**fixed)
                .map(|((x, m), _)| penalty.energy(*m, x))
                .sum(),
            _ => 0.0,
        };
        let gravitational: Real = body
            .positions
            .iter()
            .zip(&body.masses)
            .map(|(x, m)| -m * gravity.dot(x))
            .sum();
        body.kinetic_energy() + body.potential_energy() + contact + gravitational
    }

    /// The energy scale the world's watch measures gains against:
    /// `KE + U + M |g| H + M c_p^2 / 1000`, with `U` the stored energy,
    /// `H` the walls' extent along gravity, or the body's own without
    /// walls (`world/watch.rs`).
    pub fn energy_scale(&self, gravity: &Vector) -> Real {
        let body = &self.body;
        let (min, max) = body.obstacles.walls.unwrap_or_else(|| {
            body.positions.iter().fold(
                (
                    Vector::repeat(Real::INFINITY),
                    Vector::repeat(Real::NEG_INFINITY),
                ),
                |(lo, hi), x| (lo.inf(x), hi.sup(x)),
            )
        });
        let height: Real = (0..3).map(|a| gravity[a].abs() * (max[a] - min[a])).sum();
        let mass: Real = body.masses.iter().sum();
        let wave = body.params.wave_speed();
        body.kinetic_energy() + body.potential_energy() + mass * height + 1e-3 * mass * wave * wave
    }

    /// In the static scheme, the particles of a fragment the cracks have
    /// freed from every anchor, if any (the largest such): a free body
    /// under load has no static equilibrium, so its solve is meaningless.
    /// `None` in the other schemes, where a free piece just moves.
    pub fn free_in_statics(&self) -> Option<usize> {
        let statics = matches!(
            self.body.params.integrator,
            super::params::Integrator::Implicit(p) if p.scheme == super::params::ImplicitScheme::Static
        );
        if !statics {
            return None;
        }
        let fracture = self
            .body
            .fracture
            .as_ref()
            .filter(|f| f.fragment_count() > 1)?;
        let count = fracture.fragment_count() as usize;
        let (mut sizes, mut held) = (vec![0usize; count], vec![false; count]);
        for (&k, &fixed) in fracture.fragments().iter().zip(&self.body.fixed) {
            sizes[k as usize] += 1;
            held[k as usize] |= fixed;
        }
        (0..count)
            .filter(|&k| !held[k] && sizes[k] > 0)
            .map(|k| sizes[k])
            .max()
    }

    /// Whether the implicit integrator steps it.
    pub fn is_implicit(&self) -> bool {
        matches!(self.integrator, Integrator::Implicit(_))
    }

    /// Bytes held by the implicit integrator's last sparse Cholesky factor
    /// (0 before one was computed, and for other integrators): the direct
    /// solver's dominant memory.
    pub fn cholesky_factor_bytes(&self) -> usize {
        self.integrator.cholesky_factor_bytes()
    }

    /// The first particle whose state is not finite, that moves faster
    /// than ten elastic wave speeds, or whose Green strain at the last
    /// force evaluation exceeded [`Self::MAX_STRAIN`]: a blow-up, not
    /// physics (walls and obstacles can stop runaway particles, but not
    /// hide the strain they left).
    pub(crate) fn first_invalid(&self) -> Option<(usize, &'static str, Real)> {
        let body = &self.body;
        let limit = 10.0 * body.params.wave_speed() + 1e3;
        let moving = body
            .positions
            .iter()
            .zip(&body.velocities)
            .enumerate()
            .find_map(|(i, (x, v))| {
                if !x.iter().all(|c| c.is_finite()) {
                    Some((i, "position", x.norm()))
                } else {
                    let speed = v.norm();
                    (speed.is_nan() || speed > limit).then_some((i, "velocity", speed))
                }
            });
        moving.or_else(|| {
            self.integrator
                .states()
                .iter()
                .enumerate()
                .find_map(|(i, s)| {
                    let strain =
                        (s.e + body.plastic.as_ref().map_or_else(Matrix3::zeros, |p| p[i])).norm();
                    (strain.is_nan() || strain > Self::MAX_STRAIN).then_some((i, "strain", strain))
                })
        })
    }

    /// Green strain norm beyond which a solid is taken to have blown up: a
    /// stretch of about 14 times, far past any elastic material.
    pub const MAX_STRAIN: Real = 100.0;

    /// The smallest volume ratio `det F` a particle may reach: a fifth of
    /// its volume, far past what an elastic solid survives. St Venant–
    /// Kirchhoff's resistance to compression peaks at a stretch of
    /// `1/sqrt(3)` and vanishes at 0, so a soft block under its own weight
    /// flattened into one layer of particles (`det F` near 0) and stayed
    /// there as an equilibrium, with nothing in the finite-and-bounded
    /// checks of `first_invalid` to notice.
    pub const MIN_VOLUME_RATIO: Real = 0.2;

    /// The particle squeezed furthest below [`Self::MIN_VOLUME_RATIO`] at
    /// the last force evaluation, with its `det F`.
    pub(crate) fn collapsed(&self) -> Option<(usize, Real)> {
        self.integrator
            .states()
            .iter()
            .map(|s| s.det)
            .enumerate()
            .filter(|(_, det)| *det < Self::MIN_VOLUME_RATIO)
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// What to change when the solid collapses, by its material.
    pub(crate) fn collapse_advice(&self) -> &'static str {
        match self.body.params.material.model {
            Hyperelastic::StVenantKirchhoff => {
                "St Venant-Kirchhoff stops resisting compression past a stretch of 1/sqrt(3); set \
                 material = \"stable_neo_hookean\", or stiffen the solid (young, volume_stiffness)"
            }
            Hyperelastic::StableNeoHookean => {
                "the load crushes the material; stiffen it (young, volume_stiffness) or lower \
                 time.dt"
            }
        }
    }
}

impl Deref for ElasticSolid {
    type Target = Body;

    fn deref(&self) -> &Body {
        &self.body
    }
}

impl DerefMut for ElasticSolid {
    fn deref_mut(&mut self) -> &mut Body {
        &mut self.body
    }
}
