//! A modal EFG solid as a world steps it (Guo–Qin Section 5.3): the
//! discretisation and its modal basis computed once, then per step the
//! reduced state, the nodal displacements, the surface embedded in the
//! nodes' shape functions and the user's grabs (Eq. 32-33).
//!
//! Everything a step reads that never changes (the EFG solid, the rest
//! positions, the masses, the surface's shape functions) sits behind one
//! `Arc`, so a world's copy for a failed step's restore or a snapshot
//! costs the state only.

use super::estimate::{Estimate, MATRIX_ENTRY_BYTES, NODE_REALS, SHAPE_ENTRY_BYTES, SurfacePoints};
use super::nonlinear::{
    self, NewtonInfo, NewtonParams, NonlinearError, NonlinearSolver, StepInput,
};
use super::skin::{DeformedSkin, Skin, SkinBuffers, SkinInput};
use super::solid::Laps;
use super::{
    CoverError, EfgError, EfgParams, EfgSolid, FixedSurface, Material, NonlinearState, Row,
    ShapeTable, Spring,
};
use crate::cancel::Cancel;
use crate::geometry::ImplicitSurface;
use crate::geometry::octree::Octree;
use crate::math::{Real, Vector};
use crate::modal::{
    Damping, MAX_CONSTRAINTS, ModalBasis, ModalError, ModalSystem, Stabilization, rotation_integral,
};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Duration;

/// How a modal solid moves: its reduced, linearised modes, or the full
/// nonlinear EFG state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dynamics {
    /// The lowest modes with modal warping (Section 5.3; Choi & Ko):
    /// cheap per step, linear strain, which shortens a beam bent hard
    /// (`modal_warping_shortens_a_beam_bent_hard`).
    #[default]
    Modal,
    /// Every nodal coefficient under Green's strain and the St
    /// Venant–Kirchhoff energy (Section 5.1, Eq. 18-20; `nonlinear.rs`),
    /// implicit Newton steps on the consistent mass: exact large
    /// deformation at the cost of a sparse factorisation per iteration.
    /// No modes are computed.
    Nonlinear,
}

/// The knobs of a modal solid: the discretisation's and the reduced
/// model's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModalParams {
    /// Reduced modes or the full nonlinear state.
    pub dynamics: Dynamics,
    /// The EFG discretisation.
    pub efg: EfgParams,
    /// Modes kept, `l` (free bodies' six rigid modes among them).
    pub modes: usize,
    /// Relative accuracy of the eigenpairs.
    pub tolerance: Real,
    /// Modal warping (Choi & Ko 2005) or linear modes.
    pub warping: bool,
    /// Rayleigh damping `C = a M + b K`.
    pub damping: Damping,
    /// Baumgarte factors of the grabs (Eq. 33).
    pub stabilization: Stabilization,
}

/// A material point held by the user: its position, its orientation or
/// both (Section 5.3.3). Targets are in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grab {
    /// The material point, rest shape, world frame.
    pub point: Vector,
    /// Where it should be.
    pub position: Option<Vector>,
    /// The rotation vector (axis times angle, rad) it should be turned by.
    pub rotation: Option<Vector>,
}

/// Why grabs were refused; the previous ones stay.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GrabError {
    /// More constraint rows than the solver takes.
    #[error(
        "{rows} constraint rows (3 per position, 3 per orientation) are more than {max}; \
         grab fewer points"
    )]
    TooMany {
        /// Rows asked for.
        rows: usize,
        /// [`MAX_CONSTRAINTS`].
        max: usize,
    },
    /// A grab holds nothing.
    #[error("grab {index} sets neither a position nor an orientation; set one")]
    Empty {
        /// Its index.
        index: usize,
    },
    /// A coordinate is not finite.
    #[error("grab {index}: a coordinate is not finite")]
    NotFinite {
        /// Its index.
        index: usize,
    },
    /// A point is not inside the solid's discretisation.
    #[error("grab {index}: the point is not on the solid ({source}); pick a point of the solid")]
    Outside {
        /// Its index.
        index: usize,
        /// What the shape functions found.
        source: CoverError,
    },
    /// The modal solver refused the rows.
    #[error("{0}")]
    Modal(#[from] ModalError),
    /// An orientation grab on a solid with nonlinear dynamics.
    #[error(
        "grab {index} sets an orientation, which a solid with `dynamics = \"nonlinear\"` does \
         not hold (its grabs are position springs); hold two or three points instead, or use \
         `dynamics = \"modal\"`"
    )]
    Orientation {
        /// Its index.
        index: usize,
    },
}

/// Why a modal solid could not step or pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotionError {
    /// The reduced model failed.
    #[error(transparent)]
    Modal(#[from] ModalError),
    /// The nonlinear solve failed.
    #[error(transparent)]
    Nonlinear(#[from] NonlinearError),
    /// Mode posing on a solid without modes.
    #[error(
        "a solid with `dynamics = \"nonlinear\"` computes no modes, so none can be posed or \
         played back; use `dynamics = \"modal\"`"
    )]
    NoModes,
}

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepReport {
    /// Newton iterations (0 for the modal path, a direct solve).
    pub iterations: usize,
    /// Whether the Newton solve met its tolerance (always for the modal
    /// path).
    pub converged: bool,
    /// Its relative residual.
    pub residual: Real,
}

/// What never changes after the build.
#[derive(Debug)]
struct Precomputed {
    efg: EfgSolid,
    rest: Vec<Vector>,
    eigenvalues: Vec<Real>,
    zero_modes: usize,
    skin: Option<Skin>,
    /// The skin's shape functions with their gradients, for a point
    /// cloud's normals under nonlinear dynamics (`F^-T n`).
    cloud: Option<ShapeTable>,
    stabilization: Stabilization,
    timings: Vec<(&'static str, Duration)>,
}

/// The full nonlinear state and its solver's scratch.
#[derive(Debug, Clone)]
struct Full {
    state: NonlinearState,
    /// `state.displacements` as vectors.
    displacements: Vec<Vector>,
    solver: NonlinearSolver,
    springs: Vec<Spring>,
    params: NewtonParams,
    load: Vec<Real>,
}

/// The state a modal solid steps.
#[derive(Debug, Clone)]
enum Motion {
    Modal(Box<ModalSystem>),
    Full(Box<Full>),
}

/// A modal EFG solid: its discretisation, basis and state.
#[derive(Debug, Clone)]
pub struct ModalSolid {
    pre: Arc<Precomputed>,
    motion: Motion,
    grabs: Vec<Grab>,
    /// For each position grab while warping: its first row in the
    /// constraints, the rows `Phi(x_c) W` of its rotation vector and the
    /// displacement `p - x_c` it asks for (see [`Self::step`]).
    warped_targets: Vec<(usize, DMatrix<Real>, Vector)>,
    /// The constraints' current targets `b_c`.
    targets: DVector<Real>,
    /// One load per node, rebuilt each step.
    loads: Vec<Vector>,
}

/// The state, for a restore or a snapshot: the reduced one (one entry per
/// mode) or, under [`Dynamics::Nonlinear`], the full one (three per node).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ModalState {
    /// Modal amplitudes `z`, or the nodal displacement coefficients.
    pub amplitudes: Vec<Real>,
    /// Modal velocities `zdot`, or the nodal velocities.
    pub velocities: Vec<Real>,
}

/// The `3 x l` rows of one grabbed point `x_c` (Section 5.3.3).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct GrabRows {
    /// `Phi(x_c) Psi`: the displacement there.
    pub(super) position: DMatrix<Real>,
    /// `1/2 curl Phi(x_c) Psi = 1/2 sum_J grad phi_J(x_c) x Psi_J`: the
    /// rotation vector there, the curl of the shape functions at the point
    /// as Eq. 27 defines it. Interpolating the nodes' rotation vectors
    /// (`Phi(x_c) W`) instead agrees with it only where the field's curl
    /// is one the basis reproduces from the nodes' (a linear field's).
    pub(super) orientation: DMatrix<Real>,
    /// `Phi(x_c) W`: the nodes' rotation vectors interpolated, the rotation
    /// warping gives the point (what frames show, [`ModalSolid::step`]).
    pub(super) warp: DMatrix<Real>,
}

impl GrabRows {
    /// The rows at the point whose shape-function row is `row`.
    pub(super) fn at(row: &Row<'_>, basis: &ModalBasis) -> Self {
        let l = basis.mode_count();
        let mut rows = Self {
            position: DMatrix::zeros(3, l),
            orientation: DMatrix::zeros(3, l),
            warp: DMatrix::zeros(3, l),
        };
        for ((&node, &phi), grad) in row.nodes.iter().zip(row.values).zip(row.gradients) {
            let psi = basis.displacement_block(node as usize).transpose();
            rows.position += &psi * phi;
            rows.warp += basis.rotation_block(node as usize).transpose() * phi;
            // grad phi x Psi column by column: the cross product's matrix.
            rows.orientation += grad.cross_matrix() * psi * 0.5;
        }
        rows
    }
}

impl ModalSolid {
    /// Discretises `geometry`, assembles, finds the `params.modes` lowest
    /// modes and their rotation modes, and embeds `skin`.
    ///
    /// # Errors
    /// [`EfgError`] from the discretisation or the eigensolver, or a skin
    /// point the supports do not cover.
    pub fn build(
        geometry: &dyn ImplicitSurface,
        fixed: &FixedSurface,
        material: Material,
        params: &ModalParams,
        skin: Option<SkinInput>,
        cancel: &Cancel,
    ) -> Result<Self, EfgError> {
        Self::build_admitted(geometry, fixed, material, params, skin, cancel, &|_| Ok(()))
    }

    /// [`Self::build`], with `admit` asked once the octree stands, with
    /// the [`Estimate`] of everything after it, before any of that is
    /// allocated: a host reserves the bytes against its budget there, or
    /// refuses (its reason becomes [`EfgError::Refused`]).
    ///
    /// # Errors
    /// As [`Self::build`], and [`EfgError::Refused`].
    pub fn build_admitted(
        geometry: &dyn ImplicitSurface,
        fixed: &FixedSurface,
        material: Material,
        params: &ModalParams,
        skin: Option<SkinInput>,
        cancel: &Cancel,
        admit: &dyn Fn(&Estimate) -> Result<(), String>,
    ) -> Result<Self, EfgError> {
        let surface = SurfacePoints {
            fixed: &fixed.points,
            skin: skin.as_ref().map_or(&[][..], |s| s.vertices.as_slice()),
            triangles: skin.as_ref().map_or(0, |s| s.triangles.len()),
        };
        let admit_octree = |octree: &Octree| {
            let modes = match params.dynamics {
                Dynamics::Modal => params.modes,
                Dynamics::Nonlinear => 0,
            };
            let mut estimate = Estimate::of(octree, &params.efg, modes, surface, cancel)
                .map_err(|_| EfgError::Cancelled)?;
            if params.dynamics == Dynamics::Nonlinear {
                // Per Gauss point its stress and tangent; per block of K
                // the penalty's and the Newton matrix's values (the
                // factor's fill, as the eigensolver's, is not modelled).
                let real = std::mem::size_of::<Real>();
                let extra = estimate
                    .quadrature_points
                    .saturating_mul(nonlinear::POINT_BYTES)
                    .saturating_add(estimate.blocks.saturating_mul(9 * 2 * real));
                estimate.bytes = estimate.bytes.saturating_add(extra as u64);
            }
            admit(&estimate).map_err(|reason| EfgError::Refused {
                estimate: Box::new(estimate),
                reason,
            })
        };
        let efg =
            EfgSolid::build_admitted(geometry, fixed, material, params.efg, cancel, &admit_octree)?;
        let mut laps = Laps::after(efg.timings().to_vec());
        let (motion, eigenvalues, zero_modes) = match params.dynamics {
            Dynamics::Modal => {
                let modes = efg.modes(params.modes, params.tolerance, cancel)?;
                laps.lap("modes");
                let basis = efg.basis_of(&modes, cancel)?;
                laps.lap("rotation modes");
                let system = ModalSystem::new(basis, params.damping, params.warping);
                (
                    Motion::Modal(Box::new(system)),
                    modes.eigenvalues,
                    modes.zero_modes,
                )
            }
            Dynamics::Nonlinear => {
                let n = efg.nodes().len();
                let solver = NonlinearSolver::new(&efg);
                laps.lap("penalty");
                let full = Full {
                    state: NonlinearState::rest(n),
                    displacements: vec![Vector::zeros(); n],
                    solver,
                    springs: Vec::new(),
                    params: NewtonParams {
                        damping: (params.damping.alpha(), params.damping.beta()),
                        ..NewtonParams::default()
                    },
                    load: vec![0.0; 3 * n],
                };
                (Motion::Full(Box::new(full)), Vec::new(), 0)
            }
        };
        let cloud = match (&skin, params.dynamics) {
            (Some(input), Dynamics::Nonlinear) if input.triangles.is_empty() => {
                Some(efg.shape_table_cancellable(&input.vertices, cancel)?)
            }
            _ => None,
        };
        let skin = skin
            .map(|input| {
                let table = efg.shape_table_cancellable(&input.vertices, cancel)?;
                Ok::<_, EfgError>(Skin::new(input, &table))
            })
            .transpose()?;
        laps.lap("skin embedding");
        let rest: Vec<Vector> = efg.nodes().iter().map(|n| n.position).collect();
        let n = rest.len();
        Ok(Self {
            pre: Arc::new(Precomputed {
                efg,
                rest,
                eigenvalues,
                zero_modes,
                skin,
                cloud,
                stabilization: params.stabilization,
                timings: laps.timings,
            }),
            motion,
            grabs: Vec::new(),
            warped_targets: Vec::new(),
            targets: DVector::zeros(0),
            loads: vec![Vector::zeros(); n],
        })
    }

    /// The bytes it holds, counted from its arrays: the octree
    /// ([`crate::geometry::Octree::bytes`]), stiffness and mass values and
    /// their pattern's row indices, the two modal bases (`Psi`, `W`), the
    /// shape-function tables of the quadrature points (a value, a
    /// gradient and an index per entry) and of the skin (see
    /// `Skin::bytes`), and the per-node state (displacements, rotations,
    /// loads and scratch). [`Estimate`] bounds it before the build.
    pub fn bytes(&self) -> usize {
        let real = std::mem::size_of::<Real>();
        let efg = &self.pre.efg;
        let n = self.len();
        let l = self.pre.eigenvalues.len();
        let skin = self.pre.skin.as_ref().map_or(0, Skin::bytes);
        efg.octree().bytes()
            + efg.stiffness().len() * MATRIX_ENTRY_BYTES
            + 2 * 3 * n * l * real
            + efg.shape_entries() * SHAPE_ENTRY_BYTES
            + skin
            + n * NODE_REALS * real
            + match &self.motion {
                Motion::Modal(_) => 0,
                Motion::Full(full) => {
                    full.solver.bytes()
                        + self
                            .pre
                            .cloud
                            .as_ref()
                            .map_or(0, |t| t.entries() * SHAPE_ENTRY_BYTES)
                }
            }
    }

    /// Wall time of each build stage, in order: the discretisation's
    /// ([`EfgSolid::timings`]), then the modes, the rotation modes and
    /// the skin's embedding.
    pub fn timings(&self) -> &[(&'static str, Duration)] {
        &self.pre.timings
    }

    /// The discretisation.
    pub fn efg(&self) -> &EfgSolid {
        &self.pre.efg
    }

    /// Node count.
    pub fn len(&self) -> usize {
        self.pre.rest.len()
    }

    /// Whether it has no node (never, once built).
    pub fn is_empty(&self) -> bool {
        self.pre.rest.is_empty()
    }

    /// Eigenvalues `lambda = omega^2` of the kept modes, ascending.
    pub fn eigenvalues(&self) -> &[Real] {
        &self.pre.eigenvalues
    }

    /// Angular frequencies `omega = sqrt(lambda)`, rad/s.
    pub fn frequencies(&self) -> Vec<Real> {
        self.pre.eigenvalues.iter().map(|l| l.sqrt()).collect()
    }

    /// How many of the modes are rigid (zero eigenvalue).
    pub fn zero_modes(&self) -> usize {
        self.pre.zero_modes
    }

    /// Whether modal warping is on (never under nonlinear dynamics).
    pub fn warping(&self) -> bool {
        match &self.motion {
            Motion::Modal(system) => system.warping(),
            Motion::Full(_) => false,
        }
    }

    /// Its dynamics.
    pub fn dynamics(&self) -> Dynamics {
        match &self.motion {
            Motion::Modal(_) => Dynamics::Modal,
            Motion::Full(_) => Dynamics::Nonlinear,
        }
    }

    /// Rest positions of the nodes.
    pub fn rest_positions(&self) -> &[Vector] {
        &self.pre.rest
    }

    /// Nodal displacements at the current state.
    pub fn displacements(&self) -> &[Vector] {
        match &self.motion {
            Motion::Modal(system) => system.displacements(),
            Motion::Full(full) => &full.displacements,
        }
    }

    /// Node positions at the current state.
    pub fn positions(&self) -> impl Iterator<Item = Vector> + '_ {
        self.pre
            .rest
            .iter()
            .zip(self.displacements())
            .map(|(x, u)| x + u)
    }

    /// Node velocities: the local velocity `Psi_I zdot` turned by the node's
    /// rotation `R(w_I)` while warping ([`ModalSystem::node_velocity`]);
    /// the nodal velocities under nonlinear dynamics.
    pub fn velocities(&self) -> Vec<Vector> {
        match &self.motion {
            Motion::Modal(system) => (0..self.len()).map(|i| system.node_velocity(i)).collect(),
            Motion::Full(full) => full
                .state
                .velocities
                .chunks_exact(3)
                .map(|v| Vector::new(v[0], v[1], v[2]))
                .collect(),
        }
    }

    /// Lumped node masses (row sums of the consistent mass).
    pub fn masses(&self) -> &[Real] {
        self.pre.efg.node_masses()
    }

    /// Each node's share `u_I . (K u)_I / 2` of the strain energy of the
    /// linear displacement `u = Psi z`: they sum to `z^T Lambda z / 2`.
    /// Under nonlinear dynamics, its share of the St Venant–Kirchhoff
    /// energy ([`super::strain_energy_shares`]).
    pub fn elastic_energies(&self) -> Vec<Real> {
        let system = match &self.motion {
            Motion::Modal(system) => system,
            Motion::Full(full) => {
                return nonlinear::strain_energy_shares(&self.pre.efg, &full.state.displacements);
            }
        };
        let u = system.linear_displacements();
        let mut ku = faer::Mat::<Real>::zeros(u.len(), 1);
        let efg = &self.pre.efg;
        efg.pattern().multiply(
            efg.stiffness(),
            faer::MatRef::from_column_major_slice(u, u.len(), 1),
            ku.as_mut(),
        );
        u.chunks_exact(3)
            .enumerate()
            .map(|(i, u)| 0.5 * (0..3).map(|a| u[a] * ku[(3 * i + a, 0)]).sum::<Real>())
            .collect()
    }

    /// Mechanical energy under gravity `g`, J: gravity's
    /// `-sum_I m_I g . u_I` over the shown displacements, and for modal
    /// dynamics the reduced model's kinetic and strain energy
    /// `(|zdot|^2 + z^T Lambda z) / 2` (mass-normalised modes), for
    /// nonlinear dynamics the full state's kinetic, Saint Venant–Kirchhoff
    /// and penalty energy. Exact for linear modes, where the modal load is
    /// `Psi^T M g` and the lumped masses are the consistent mass's row
    /// sums; with warping the load turns with the nodes and this is the
    /// energy of the shown state.
    pub fn mechanical_energy(&self, g: &Vector) -> Real {
        let stored = match &self.motion {
            Motion::Modal(system) => {
                let strain: Real = system
                    .amplitudes()
                    .iter()
                    .zip(&self.pre.eigenvalues)
                    .map(|(z, lambda)| lambda * z * z)
                    .sum();
                0.5 * (system.velocities().norm_squared() + strain)
            }
            Motion::Full(full) => full.solver.stored_energy(&self.pre.efg, &full.state),
        };
        let gravity: Real = self
            .displacements()
            .iter()
            .zip(self.masses())
            .map(|(u, m)| -m * g.dot(u))
            .sum();
        stored + gravity
    }

    /// What to change when a step gained energy, by the dynamics: a
    /// modal step's only source is warping turning the load; a nonlinear
    /// one's a Newton solve stopped at its cap.
    pub fn energy_advice(&self) -> &'static str {
        match self.motion {
            Motion::Modal(_) => {
                "the only source in a modal step is warping turning the load with the nodes: \
                 lower time.dt or set warping = false"
            }
            Motion::Full(_) => {
                "its Newton solves did not converge or overshot: lower time.dt, or add damping"
            }
        }
    }

    /// The scale the world's energy watch measures gains against:
    /// `E_kin + E_strain + M |g| H + M c^2 / 1000` (`H` the rest extent
    /// along gravity, `c = sqrt(E / rho)`), as for the MLS solids.
    pub fn energy_scale(&self, g: &Vector) -> Real {
        let (min, max) = self.rest_positions().iter().fold(
            (
                Vector::repeat(Real::INFINITY),
                Vector::repeat(Real::NEG_INFINITY),
            ),
            |(lo, hi), x| (lo.inf(x), hi.sup(x)),
        );
        let height: Real = (0..3).map(|a| g[a].abs() * (max[a] - min[a])).sum();
        let mass: Real = self.masses().iter().sum();
        let material = self.pre.efg.material();
        let stored = self.mechanical_energy(&Vector::zeros());
        stored + mass * height + 1e-3 * mass * material.young / material.density
    }

    /// Advances by `h` under gravity `g`, with the grabs in force.
    ///
    /// With warping on, a position grab's rows constrain the linear field
    /// `u_L(x_c)`, while the point is shown at the warped
    /// `R(w(x_c)) u_L(x_c)` (`R` the rotation integral, Choi & Ko). So
    /// before each step its target is set to `R(w)^-1 (p - x_c)` at the
    /// current rotation `w`: a fixed point that puts the warped point at
    /// `p` once the motion settles, at the cost of three 3x3 products per
    /// grab and no refactoring (only the targets move).
    ///
    /// Under nonlinear dynamics, one backward-Euler step minimised by
    /// Newton ([`NonlinearSolver::step`]); `cancel` is read per iteration.
    ///
    /// # Errors
    /// [`MotionError`] for a bad step, an overflow, a failed or cancelled
    /// solve; the state is then unchanged.
    pub fn step(&mut self, h: Real, g: &Vector) -> Result<StepReport, MotionError> {
        self.step_cancellable(h, g, &Cancel::new())
    }

    /// [`Self::step`] reading `cancel`.
    ///
    /// # Errors
    /// As [`Self::step`].
    pub fn step_cancellable(
        &mut self,
        h: Real,
        g: &Vector,
        cancel: &Cancel,
    ) -> Result<StepReport, MotionError> {
        let system = match &mut self.motion {
            Motion::Modal(system) => system,
            Motion::Full(full) => {
                let efg = &self.pre.efg;
                for (f, m) in full.load.chunks_exact_mut(3).zip(efg.node_masses()) {
                    for (a, f) in f.iter_mut().enumerate() {
                        *f = g[a] * m;
                    }
                }
                let info: NewtonInfo = full.solver.step(
                    efg,
                    &mut full.state,
                    StepInput {
                        h: Some(h),
                        load: &full.load,
                        springs: &full.springs,
                    },
                    &full.params,
                    cancel,
                )?;
                for (d, u) in full
                    .displacements
                    .iter_mut()
                    .zip(full.state.displacements.chunks_exact(3))
                {
                    *d = Vector::new(u[0], u[1], u[2]);
                }
                return Ok(StepReport {
                    iterations: info.iterations,
                    converged: info.converged,
                    residual: info.residual,
                });
            }
        };
        for (f, m) in self.loads.iter_mut().zip(self.pre.efg.node_masses()) {
            *f = g * *m;
        }
        if system.warping() && !self.warped_targets.is_empty() {
            let z = system.amplitudes();
            for (row, rotation_rows, wanted) in &self.warped_targets {
                let w = Vector::from_iterator((rotation_rows * z).iter().copied());
                let linear = rotation_integral(&w)
                    .try_inverse()
                    .map_or(*wanted, |inverse| inverse * wanted);
                for c in 0..3 {
                    self.targets[row + c] = linear[c];
                }
            }
            system.set_constraint_targets(&self.targets)?;
        }
        system.step(h, &self.loads)?;
        Ok(StepReport {
            iterations: 0,
            converged: true,
            residual: 0.0,
        })
    }

    /// Poses mode `mode` at amplitude `amplitude` at rest (the playback
    /// of a mode shape).
    ///
    /// # Errors
    /// [`ModalError`] when the amplitude is not finite; an out-of-range
    /// mode is a [`ModalError::Shape`]; [`MotionError::NoModes`] under
    /// nonlinear dynamics.
    pub fn pose_mode(&mut self, mode: usize, amplitude: Real) -> Result<(), MotionError> {
        let Motion::Modal(system) = &mut self.motion else {
            return Err(MotionError::NoModes);
        };
        let l = self.pre.eigenvalues.len();
        if mode >= l {
            return Err(ModalError::Shape {
                what: "mode",
                expected_rows: l,
                expected_cols: 1,
                got_rows: mode + 1,
                got_cols: 1,
            }
            .into());
        }
        let mut z = DVector::zeros(l);
        z[mode] = amplitude;
        Ok(system.set_state(&z, &DVector::zeros(l))?)
    }

    /// The modal static solution under gravity `g`, at rest: `z_j =
    /// Psi_j^T f / lambda_j` with `f` the nodal weights, for the kept
    /// elastic modes; a rigid mode, which has no static response, at 0.
    /// Truncated to the kept modes, so it measures what reduction costs.
    /// Empty under nonlinear dynamics, which has no modes.
    pub fn static_state(&self, g: &Vector) -> ModalState {
        let Motion::Modal(system) = &self.motion else {
            return ModalState::default();
        };
        let basis = system.basis();
        let mut work = DVector::zeros(self.pre.eigenvalues.len());
        for (node, m) in self.pre.efg.node_masses().iter().enumerate() {
            work += basis.displacement_block(node) * (g * *m);
        }
        ModalState {
            amplitudes: work
                .iter()
                .zip(&self.pre.eigenvalues)
                .map(|(w, lambda)| if *lambda > 0.0 { w / lambda } else { 0.0 })
                .collect(),
            velocities: vec![0.0; work.len()],
        }
    }

    /// The state: reduced (per mode), or full (per node and axis) under
    /// nonlinear dynamics.
    pub fn state(&self) -> ModalState {
        match &self.motion {
            Motion::Modal(system) => ModalState {
                amplitudes: system.amplitudes().as_slice().to_vec(),
                velocities: system.velocities().as_slice().to_vec(),
            },
            Motion::Full(full) => ModalState {
                amplitudes: full.state.displacements.clone(),
                velocities: full.state.velocities.clone(),
            },
        }
    }

    /// The length of each vector of [`Self::state`]: the mode count, or
    /// three per node under nonlinear dynamics.
    pub fn state_len(&self) -> usize {
        match &self.motion {
            Motion::Modal(_) => self.pre.eigenvalues.len(),
            Motion::Full(_) => 3 * self.len(),
        }
    }

    /// Sets the state.
    ///
    /// # Errors
    /// [`ModalError`] when a vector's length is not [`Self::state_len`]
    /// or a value is not finite; nothing changes then.
    pub fn set_state(&mut self, state: &ModalState) -> Result<(), ModalError> {
        let full = match &mut self.motion {
            Motion::Modal(system) => {
                return system.set_state(
                    &DVector::from_column_slice(&state.amplitudes),
                    &DVector::from_column_slice(&state.velocities),
                );
            }
            Motion::Full(full) => full,
        };
        let expected = full.state.displacements.len();
        for (what, v) in [
            ("nonlinear displacements", &state.amplitudes),
            ("nonlinear velocities", &state.velocities),
        ] {
            if v.len() != expected {
                return Err(ModalError::Shape {
                    what,
                    expected_rows: expected,
                    expected_cols: 1,
                    got_rows: v.len(),
                    got_cols: 1,
                });
            }
            if let Some(row) = v.iter().position(|x| !x.is_finite()) {
                return Err(ModalError::NotFinite {
                    what,
                    row,
                    col: 0,
                    value: v[row],
                });
            }
        }
        full.state.displacements.clone_from(&state.amplitudes);
        full.state.velocities.clone_from(&state.velocities);
        for (d, u) in full
            .displacements
            .iter_mut()
            .zip(state.amplitudes.chunks_exact(3))
        {
            *d = Vector::new(u[0], u[1], u[2]);
        }
        Ok(())
    }

    /// The grabs in force.
    pub fn grabs(&self) -> &[Grab] {
        &self.grabs
    }

    /// Replaces the grabs: each position grab is the three rows
    /// `Phi(x_c) Psi` with target `p - x_c`, each orientation grab the
    /// three rows `1/2 curl Phi(x_c) Psi` with target the rotation vector
    /// (Eq. 32, the rotation of Eq. 27 at the grabbed point).
    /// The rows constrain the linear modal field; with warping on, a
    /// position target is met by the linear displacement, which the
    /// warped one differs from at second order in the rotation.
    ///
    /// # Errors
    /// [`GrabError`]; the previous grabs then stay.
    pub fn set_grabs(&mut self, grabs: &[Grab]) -> Result<(), GrabError> {
        let mut rows = 0;
        for (index, g) in grabs.iter().enumerate() {
            if g.position.is_none() && g.rotation.is_none() {
                return Err(GrabError::Empty { index });
            }
            let finite = [Some(g.point), g.position, g.rotation]
                .iter()
                .flatten()
                .all(|v| v.iter().all(|c| c.is_finite()));
            if !finite {
                return Err(GrabError::NotFinite { index });
            }
            rows += 3 * (usize::from(g.position.is_some()) + usize::from(g.rotation.is_some()));
        }
        if rows > MAX_CONSTRAINTS {
            return Err(GrabError::TooMany {
                rows,
                max: MAX_CONSTRAINTS,
            });
        }
        let system = match &mut self.motion {
            Motion::Modal(system) => system,
            Motion::Full(full) => {
                let mut springs = Vec::with_capacity(grabs.len());
                let efg = &self.pre.efg;
                // As stiff as a hundred octant-sized cubes of the material
                // in series with nothing: it holds the point to about 1 %
                // of the deformation of the octant around it.
                let stiffness = 100.0 * efg.material().young * efg.params().cell;
                for (index, g) in grabs.iter().enumerate() {
                    if g.rotation.is_some() {
                        return Err(GrabError::Orientation { index });
                    }
                    let table = efg
                        .shape_table(std::slice::from_ref(&g.point))
                        .map_err(|source| GrabError::Outside { index, source })?;
                    let row = table.row(0);
                    if let Some(p) = g.position {
                        springs.push(Spring {
                            nodes: row.nodes.to_vec(),
                            values: row.values.to_vec(),
                            target: p - g.point,
                            stiffness,
                        });
                    }
                }
                full.springs = springs;
                self.grabs = grabs.to_vec();
                return Ok(());
            }
        };
        let l = self.pre.eigenvalues.len();
        let mut a = DMatrix::zeros(rows, l);
        let mut b = DVector::zeros(rows);
        let mut warped_targets = Vec::new();
        let basis = system.basis();
        let mut r = 0;
        for (index, g) in grabs.iter().enumerate() {
            let table = self
                .pre
                .efg
                .shape_table(std::slice::from_ref(&g.point))
                .map_err(|source| GrabError::Outside { index, source })?;
            let rows = GrabRows::at(&table.row(0), basis);
            if let Some(p) = g.position {
                let wanted = p - g.point;
                a.rows_mut(r, 3).copy_from(&rows.position);
                b.rows_mut(r, 3).copy_from(&wanted);
                warped_targets.push((r, rows.warp, wanted));
                r += 3;
            }
            if let Some(w) = g.rotation {
                a.rows_mut(r, 3).copy_from(&rows.orientation);
                b.rows_mut(r, 3).copy_from(&w);
                r += 3;
            }
        }
        system.set_constraints(&a, &b, self.pre.stabilization)?;
        self.grabs = grabs.to_vec();
        self.warped_targets = warped_targets;
        self.targets = b;
        Ok(())
    }

    /// `|A_c z - b_c|` of the grabs at the current state (under
    /// nonlinear dynamics, of the springs: `|sum_I phi_I u_I - d|` stacked).
    pub fn grab_violation(&self) -> Real {
        match &self.motion {
            Motion::Modal(system) => system.constraint_violation(),
            Motion::Full(full) => full
                .springs
                .iter()
                .map(|s| {
                    let mut x = -s.target;
                    for (&n, &phi) in s.nodes.iter().zip(&s.values) {
                        x += full.displacements[n as usize] * phi;
                    }
                    x.norm_squared()
                })
                .sum::<Real>()
                .sqrt(),
        }
    }

    /// The deformed skin: positions and unit normals (recomputed from the
    /// triangles of a mesh; for a point cloud the rest normals turned by
    /// the interpolated rotation vector `R(w(x))`). `None` without one.
    pub fn skin(&self) -> Option<DeformedSkin<'_>> {
        let mut buffers = SkinBuffers::default();
        let triangles = self.skin_into(&mut buffers)?;
        Some(DeformedSkin {
            positions: buffers.positions,
            triangles,
            normals: buffers.normals,
        })
    }

    /// [`Self::skin`] into buffers a caller reuses from frame to frame;
    /// returns the triangles, or `None` (buffers untouched) without a
    /// skin.
    pub fn skin_into(&self, buffers: &mut SkinBuffers) -> Option<&[[u32; 3]]> {
        let skin = self.pre.skin.as_ref()?;
        match &self.motion {
            Motion::Modal(system) => skin.deform_into(system, buffers),
            Motion::Full(full) => {
                skin.deform_full_into(&full.displacements, self.pre.cloud.as_ref(), buffers);
            }
        }
        Some(skin.triangles())
    }

    /// Turns modal warping on or off from now on (the same state shown
    /// warped or linear), to measure what warping costs and changes.
    /// Nothing under nonlinear dynamics.
    pub fn set_warping(&mut self, warping: bool) {
        if let Motion::Modal(system) = &mut self.motion {
            system.set_warping(warping);
        }
    }
}
