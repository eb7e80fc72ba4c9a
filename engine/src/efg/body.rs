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
use super::skin::{DeformedSkin, Skin, SkinBuffers, SkinInput};
use super::solid::Laps;
use super::{CoverError, EfgError, EfgParams, EfgSolid, FixedSurface, Material, Row};
use crate::Cancel;
use crate::geometry::ImplicitSurface;
use crate::geometry::octree::Octree;
use crate::math::{Real, Vector};
use crate::modal::{
    Damping, MAX_CONSTRAINTS, ModalBasis, ModalError, ModalSystem, Stabilization, rotation_integral,
};
use nalgebra::{DMatrix, DVector};
use std::sync::Arc;
use std::time::Duration;

/// The knobs of a modal solid: the discretisation's and the reduced
/// model's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModalParams {
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
}

/// What never changes after the build.
#[derive(Debug)]
struct Precomputed {
    efg: EfgSolid,
    rest: Vec<Vector>,
    eigenvalues: Vec<Real>,
    zero_modes: usize,
    skin: Option<Skin>,
    stabilization: Stabilization,
    timings: Vec<(&'static str, Duration)>,
}

/// A modal EFG solid: its discretisation, basis and state.
#[derive(Debug, Clone)]
pub struct ModalSolid {
    pre: Arc<Precomputed>,
    system: ModalSystem,
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

/// The reduced state, for a restore or a snapshot.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ModalState {
    /// Modal amplitudes `z`.
    pub amplitudes: Vec<Real>,
    /// Modal velocities `zdot`.
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
            let estimate = Estimate::of(octree, &params.efg, params.modes, surface, cancel)
                .map_err(|_| EfgError::Cancelled)?;
            admit(&estimate).map_err(|reason| EfgError::Refused {
                estimate: Box::new(estimate),
                reason,
            })
        };
        let efg =
            EfgSolid::build_admitted(geometry, fixed, material, params.efg, cancel, &admit_octree)?;
        let mut laps = Laps::after(efg.timings().to_vec());
        let modes = efg.modes(params.modes, params.tolerance, cancel)?;
        laps.lap("modes");
        let basis = efg.basis_of(&modes, cancel)?;
        laps.lap("rotation modes");
        let skin = skin
            .map(|input| {
                let table = efg.shape_table_cancellable(&input.vertices, cancel)?;
                Ok::<_, EfgError>(Skin::new(input, &table))
            })
            .transpose()?;
        laps.lap("skin embedding");
        let rest: Vec<Vector> = efg.nodes().iter().map(|n| n.position).collect();
        let n = rest.len();
        let system = ModalSystem::new(basis, params.damping, params.warping);
        Ok(Self {
            pre: Arc::new(Precomputed {
                efg,
                rest,
                eigenvalues: modes.eigenvalues,
                zero_modes: modes.zero_modes,
                skin,
                stabilization: params.stabilization,
                timings: laps.timings,
            }),
            system,
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

    /// Whether modal warping is on.
    pub fn warping(&self) -> bool {
        self.system.warping()
    }

    /// Rest positions of the nodes.
    pub fn rest_positions(&self) -> &[Vector] {
        &self.pre.rest
    }

    /// Nodal displacements at the current state.
    pub fn displacements(&self) -> &[Vector] {
        self.system.displacements()
    }

    /// Node positions at the current state.
    pub fn positions(&self) -> impl Iterator<Item = Vector> + '_ {
        self.pre
            .rest
            .iter()
            .zip(self.system.displacements())
            .map(|(x, u)| x + u)
    }

    /// Node velocities: the local velocity `Psi_I zdot` turned by the node's
    /// rotation `R(w_I)` while warping ([`ModalSystem::node_velocity`]).
    pub fn velocities(&self) -> Vec<Vector> {
        (0..self.len())
            .map(|i| self.system.node_velocity(i))
            .collect()
    }

    /// Lumped node masses (row sums of the consistent mass).
    pub fn masses(&self) -> &[Real] {
        self.pre.efg.node_masses()
    }

    /// Each node's share `u_I . (K u)_I / 2` of the strain energy of the
    /// linear displacement `u = Psi z`: they sum to `z^T Lambda z / 2`.
    pub fn elastic_energies(&self) -> Vec<Real> {
        let u = self.system.linear_displacements();
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

    /// Mechanical energy under gravity `g`: the reduced model's kinetic
    /// and strain energy `(|zdot|^2 + z^T Lambda z) / 2` (mass-normalised
    /// modes) and gravity's `-sum_I m_I g . u_I` over the shown
    /// displacements, J. Exact for linear modes, where the modal load is
    /// `Psi^T M g` and the lumped masses are the consistent mass's row
    /// sums; with warping the load turns with the nodes and this is the
    /// energy of the shown state.
    pub fn mechanical_energy(&self, g: &Vector) -> Real {
        let z = self.system.amplitudes();
        let zdot = self.system.velocities();
        let strain: Real = z
            .iter()
            .zip(&self.pre.eigenvalues)
            .map(|(z, lambda)| lambda * z * z)
            .sum();
        let gravity: Real = self
            .displacements()
            .iter()
            .zip(self.masses())
            .map(|(u, m)| -m * g.dot(u))
            .sum();
        0.5 * (zdot.norm_squared() + strain) + gravity
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
    /// # Errors
    /// [`ModalError`] for a bad step or an overflow; the state is then
    /// unchanged.
    pub fn step(&mut self, h: Real, g: &Vector) -> Result<(), ModalError> {
        for (f, m) in self.loads.iter_mut().zip(self.pre.efg.node_masses()) {
            *f = g * *m;
        }
        if self.system.warping() && !self.warped_targets.is_empty() {
            let z = self.system.amplitudes();
            for (row, rotation_rows, wanted) in &self.warped_targets {
                let w = Vector::from_iterator((rotation_rows * z).iter().copied());
                let linear = rotation_integral(&w)
                    .try_inverse()
                    .map_or(*wanted, |inverse| inverse * wanted);
                for c in 0..3 {
                    self.targets[row + c] = linear[c];
                }
            }
            self.system.set_constraint_targets(&self.targets)?;
        }
        self.system.step(h, &self.loads)
    }

    /// Poses mode `mode` at amplitude `amplitude` at rest (the playback
    /// of a mode shape).
    ///
    /// # Errors
    /// [`ModalError`] when the amplitude is not finite; an out-of-range
    /// mode is a [`ModalError::Shape`].
    pub fn pose_mode(&mut self, mode: usize, amplitude: Real) -> Result<(), ModalError> {
        let l = self.pre.eigenvalues.len();
        if mode >= l {
            return Err(ModalError::Shape {
                what: "mode",
                expected_rows: l,
                expected_cols: 1,
                got_rows: mode + 1,
                got_cols: 1,
            });
        }
        let mut z = DVector::zeros(l);
        z[mode] = amplitude;
        self.system.set_state(&z, &DVector::zeros(l))
    }

    /// The modal static solution under gravity `g`, at rest: `z_j =
    /// Psi_j^T f / lambda_j` with `f` the nodal weights, for the kept
    /// elastic modes; a rigid mode, which has no static response, at 0.
    /// Truncated to the kept modes, so it measures what reduction costs.
    pub fn static_state(&self, g: &Vector) -> ModalState {
        let basis = self.system.basis();
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

    /// The reduced state.
    pub fn state(&self) -> ModalState {
        ModalState {
            amplitudes: self.system.amplitudes().as_slice().to_vec(),
            velocities: self.system.velocities().as_slice().to_vec(),
        }
    }

    /// Sets the reduced state.
    ///
    /// # Errors
    /// [`ModalError`] when a vector's length is not the mode count or a
    /// value is not finite; nothing changes then.
    pub fn set_state(&mut self, state: &ModalState) -> Result<(), ModalError> {
        self.system.set_state(
            &DVector::from_column_slice(&state.amplitudes),
            &DVector::from_column_slice(&state.velocities),
        )
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
        let l = self.pre.eigenvalues.len();
        let mut a = DMatrix::zeros(rows, l);
        let mut b = DVector::zeros(rows);
        let mut warped_targets = Vec::new();
        let basis = self.system.basis();
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
        self.system
            .set_constraints(&a, &b, self.pre.stabilization)?;
        self.grabs = grabs.to_vec();
        self.warped_targets = warped_targets;
        self.targets = b;
        Ok(())
    }

    /// `|A_c z - b_c|` of the grabs at the current state.
    pub fn grab_violation(&self) -> Real {
        self.system.constraint_violation()
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
        skin.deform_into(&self.system, buffers);
        Some(skin.triangles())
    }

    /// Turns modal warping on or off from now on (the same state shown
    /// warped or linear), to measure what warping costs and changes.
    pub fn set_warping(&mut self, warping: bool) {
        self.system.set_warping(warping);
    }
}
