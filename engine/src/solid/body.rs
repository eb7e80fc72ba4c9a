//! The body of an MLS elastic solid: its particles, reference shape and
//! state, and nothing an integrator reuses between steps (that scratch
//! lives in `integrate/`), so a snapshot of a body is its state.

use super::contact::Obstacles;
use super::fracture::{Fracture, FractureParamsError};
use super::params::SolidParams;
use super::topology::Topology;
use crate::approx::mls::{MlsError, Order};
use crate::math::{Real, Vector};
use nalgebra::Matrix3;

/// A body sampled by particles whose elastic forces come from the MLS
/// displacement gradient in material coordinates (tutorial Section 7.1).
#[derive(Debug, Clone)]
pub struct Body {
    /// Material, discretisation and integrator; the integrator is built
    /// from `params.integrator` with the solid.
    pub params: SolidParams,
    /// Reference (material) positions `X`.
    pub(super) rest: Vec<Vector>,
    /// Current positions `x`, m.
    pub positions: Vec<Vector>,
    /// Current velocities, m/s.
    pub velocities: Vec<Vector>,
    /// Reference volume and mass of each particle.
    pub(super) volumes: Vec<Real>,
    pub(super) masses: Vec<Real>,
    /// Anchored particles: they never move.
    pub(super) fixed: Vec<bool>,
    pub(super) topology: Topology,
    /// Plastic strain per particle, only when the solid is plastic.
    pub(super) plastic: Option<Vec<Matrix3<Real>>>,
    pub(super) obstacles: Obstacles,
    /// Cracks and the pairs they cut, only when the solid fractures.
    pub(super) fracture: Option<Fracture>,
    /// Each particle's support radius once resampling split some
    /// (`resampling.rs`); `None` while all have `params.support`.
    pub(super) radii: Option<Vec<Real>>,
    /// The particles the solid was built with: the first `built` are the
    /// scene's, the rest were split off them.
    pub(super) built: usize,
    /// The most particles the solid may hold (more than it was built
    /// with only when it resamples).
    pub(super) capacity: usize,
    /// `Body::stiffness` as built, which the explicit step limit of a
    /// solid that split is measured against (`resampling.rs`).
    pub(super) built_stiffness: Real,
}

/// Why a solid cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolidError {
    /// The shape sampled no particle.
    #[error("the solid has no particles; enlarge its shape or shrink its spacing")]
    Empty,
    /// A per-particle input has the wrong length.
    #[error("{what}: expected one entry per particle ({expected}), got {got}")]
    Length {
        /// Which input.
        what: &'static str,
        /// The particle count.
        expected: usize,
        /// Its length.
        got: usize,
    },
    /// The MLS gradients cannot be built.
    #[error(transparent)]
    Mls(#[from] MlsError),
    /// The fracture parameters are refused.
    #[error(transparent)]
    Fracture(#[from] FractureParamsError),
}

impl Body {
    /// A body at rest shape `rest` with initial `velocities` and the
    /// particles flagged in `fixed` anchored, colliding with `obstacles`.
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
        let n = rest.len();
        if n == 0 {
            return Err(SolidError::Empty);
        }
        for (what, got) in [("velocities", velocities.len()), ("fixed", fixed.len())] {
            if got != n {
                return Err(SolidError::Length {
                    what,
                    expected: n,
                    got,
                });
            }
        }
        if let Some(fracture) = params.fracture {
            let rebases = params.plasticity.is_some_and(|p| p.rebase.is_some());
            fracture.validate(params.spacing, params.plasticity.is_some(), rebases)?;
        }
        let topology = Topology::build(&rest, params.dim, params.order, params.support)?;
        let fracture = params
            .fracture
            .map(|f| Fracture::new(f, n, topology.owner.len()));
        let volume = params.particle_volume();
        let mut velocities = velocities;
        for (v, &f) in velocities.iter_mut().zip(&fixed) {
            if f {
                *v = Vector::zeros();
            }
        }
        let mut body = Self {
            positions: rest.clone(),
            rest,
            velocities,
            volumes: vec![volume; n],
            masses: vec![volume * params.density; n],
            fixed,
            topology,
            plastic: params.plasticity.map(|_| vec![Matrix3::zeros(); n]),
            obstacles,
            fracture,
            radii: None,
            built_stiffness: 0.0,
            built: n,
            capacity: params
                .fracture
                .and_then(|f| f.resample)
                .map_or(n, |r| r.capacity(n).max(n)),
            params,
        };
        body.label_fragments();
        if body.params.fracture.is_some_and(|f| f.resample.is_some()) {
            body.built_stiffness = body.stiffness();
        }
        Ok(body)
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the body has no particles (never, once built).
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Reference positions.
    pub fn rest_positions(&self) -> &[Vector] {
        &self.rest
    }

    /// Particle masses, kg.
    pub fn masses(&self) -> &[Real] {
        &self.masses
    }

    /// Whether particle `i` is anchored.
    pub fn is_fixed(&self, i: usize) -> bool {
        self.fixed[i]
    }

    /// The MLS order each particle's gradient actually uses (lower than
    /// requested where its neighbourhood is degenerate).
    pub fn orders(&self) -> &[Order] {
        self.topology.gradients.orders()
    }

    /// Moves the particles to `positions` with `velocities` (a deformed
    /// initial state, say), keeping the reference shape.
    ///
    /// # Errors
    /// [`SolidError::Length`] when either has the wrong length.
    pub fn set_state(
        &mut self,
        positions: Vec<Vector>,
        velocities: Vec<Vector>,
    ) -> Result<(), SolidError> {
        for (what, got) in [
            ("positions", positions.len()),
            ("velocities", velocities.len()),
        ] {
            if got != self.len() {
                return Err(SolidError::Length {
                    what,
                    expected: self.len(),
                    got,
                });
            }
        }
        self.positions = positions;
        self.velocities = velocities;
        Ok(())
    }

    /// `grad u = F - I` of every particle, for surface embedding.
    pub fn displacement_gradients(&self, out: &mut Vec<Matrix3<Real>>) {
        out.clear();
        out.extend(
            self.current_states()
                .iter()
                .map(|s| s.f - Matrix3::identity()),
        );
    }

    /// Current density `m / (V det F)` of every particle.
    pub fn densities(&self) -> Vec<Real> {
        self.current_states()
            .iter()
            .zip(&self.masses)
            .zip(&self.volumes)
            .map(|((s, m), v)| m / (v * s.det.max(Real::EPSILON)))
            .collect()
    }

    /// Mean compressive stress `-tr(sigma) / 3` of every particle, with
    /// the Cauchy stress `sigma = P F^T / det F`, Pa.
    pub fn pressures(&self) -> Vec<Real> {
        let material = self.params.material;
        self.current_states()
            .iter()
            .map(|s| {
                let p = material.first_piola(s);
                -(p * s.f.transpose()).trace() / (3.0 * s.det.max(Real::EPSILON))
            })
            .collect()
    }

    /// Each particle's stored elastic energy `V_i W(F_i)` (strain and
    /// volume terms; the hourglass term, a numerical penalty, left out),
    /// J.
    pub fn elastic_energies(&self) -> Vec<Real> {
        let material = self.params.material;
        self.current_states()
            .iter()
            .zip(&self.volumes)
            .map(|(s, v)| v * material.energy_density(s))
            .collect()
    }

    /// Kinetic energy, J.
    pub fn kinetic_energy(&self) -> Real {
        self.velocities
            .iter()
            .zip(&self.masses)
            .map(|(v, m)| 0.5 * m * v.norm_squared())
            .sum()
    }

    /// Total volume `sum V_i det F_i`, m^3 (area in 2D).
    pub fn current_volume(&self) -> Real {
        self.current_states()
            .iter()
            .zip(&self.volumes)
            .map(|(s, v)| v * s.det)
            .sum()
    }
}

/// What a failed step restores: positions, velocities, plastic strain
/// and cracks.
#[derive(Debug, Clone, Default)]
pub struct SolidState {
    positions: Vec<Vector>,
    velocities: Vec<Vector>,
    plastic: Option<Vec<Matrix3<Real>>>,
    fracture: Option<Fracture>,
}

impl Body {
    /// Copies the state into `out`, reusing its buffers.
    pub fn save(&self, out: &mut SolidState) {
        out.positions.clone_from(&self.positions);
        out.velocities.clone_from(&self.velocities);
        out.plastic.clone_from(&self.plastic);
        out.fracture.clone_from(&self.fracture);
    }

    /// Returns to a state saved by [`Self::save`] (of this body). A
    /// reference shape re-based since is kept: re-basing is a change of
    /// description, not of state.
    pub fn restore(&mut self, saved: &SolidState) {
        self.positions.clone_from(&saved.positions);
        self.velocities.clone_from(&saved.velocities);
        self.plastic.clone_from(&saved.plastic);
        if let Some(fracture) = &saved.fracture {
            self.put_back_cracks(fracture);
        }
    }
}
