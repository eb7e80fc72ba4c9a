//! One EFG solid: its octree, quadrature, shape functions and assembled
//! matrices, built stage by stage from an implicit surface, a material and
//! the fixed part of its surface.

use super::assemble::{self, Integral};
use super::quadrature::{MAX_ORDER, Quadrature};
use super::shape::{CoverError, ShapeTable};
use crate::approx::mls::Order;
use crate::cancel::Cancel;
use crate::geometry::octree::{Node, Octree, OctreeError, OctreeParams};
use crate::geometry::{ImplicitSurface, TriMesh};
use crate::linalg::{BlockPattern, SparseCholesky};
use crate::math::{Brief, Real, Vector};
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

/// The mass matrix's form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MassForm {
    /// `int rho phi_I phi_J` (Eq. 16-17): the Galerkin mass, exact for
    /// the discretisation, sparse like K.
    Consistent,
    /// Its row sums on the diagonal: cheaper to factor and never couples
    /// nodes, at the price of lower frequencies. The test
    /// `the_lumped_mass_weighs_the_cantilever_and_lowers_its_frequency`
    /// (`efg/tests/paths.rs`) measures it: the same total mass `rho V`,
    /// and the first bending frequency of an L/H = 10 cantilever on H/4
    /// octants 0.08 % below the consistent mass's.
    Lumped,
}

/// The knobs of the discretisation; each trades speed for accuracy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EfgParams {
    /// Side of the octants at the surface: the resolution (the octree's
    /// depth follows from it and the size of the solid).
    pub cell: Real,
    /// Levels by which interior octants may be coarser than `cell`.
    pub interior_levels: u32,
    /// Support side over octant side (Section 4.1.1).
    pub alpha: Real,
    /// MLS basis: linear (Eq. 10) or quadratic (Eq. 11). The quadratic
    /// one needs three layers of nodes under every point, which the
    /// paper's `alpha = 3` does not give by a box's corners (2 x 2 x 2
    /// nodes: the build is refused as uncovered); the box cantilever of
    /// `efg/tests/paths.rs` builds at `alpha = 4.5`.
    pub basis: Order,
    /// Gauss points per axis of an integration cell (1..=5).
    pub quadrature_order: usize,
    /// Integration cells per axis of an interior octant.
    pub subdivision: usize,
    /// How many times finer boundary octants are cut than interior ones:
    /// the resolution of the cut cells' volume.
    pub boundary_refinement: usize,
    /// Consistent or lumped mass.
    pub mass: MassForm,
    /// Penalty for fixed regions, in units of `E / cell`.
    pub penalty: Real,
}

impl EfgParams {
    /// The defaults at resolution `cell`: alpha 3 and a linear basis as
    /// the paper, 2 Gauss points per axis on 2 cells per axis in every
    /// octant, consistent mass, penalty 1e4.
    pub fn new(cell: Real) -> Self {
        Self {
            cell,
            interior_levels: 0,
            alpha: 3.0,
            basis: Order::Linear,
            quadrature_order: 2,
            subdivision: 2,
            boundary_refinement: 1,
            mass: MassForm::Consistent,
            penalty: 1e4,
        }
    }
}

/// A linear isotropic elastic material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Density (mass per volume).
    pub density: Real,
    /// Young's modulus (force per area).
    pub young: Real,
    /// Poisson's ratio, in [0, 0.5).
    pub poisson: Real,
}

/// The fixed part of the surface: points with the areas they stand for,
/// where the penalty holds the displacement at zero.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FixedSurface {
    /// Points on the surface.
    pub points: Vec<Vector>,
    /// The area each point stands for.
    pub areas: Vec<Real>,
}

impl FixedSurface {
    /// The triangles of `mesh` whose three corners lie in the box
    /// `[min, max]`, each integrated by its three-point rule (points at
    /// barycentric `(2/3, 1/6, 1/6)` and permutations, exact for
    /// quadratics).
    pub fn of_mesh_in_box(mesh: &TriMesh, min: &Vector, max: &Vector) -> Self {
        let inside = |p: &Vector| (0..3).all(|k| p[k] >= min[k] && p[k] <= max[k]);
        let mut fixed = Self::default();
        for t in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.corners(t);
            if !(inside(&a) && inside(&b) && inside(&c)) {
                continue;
            }
            let area = 0.5 * (b - a).cross(&(c - a)).norm();
            for (p, q, r) in [(a, b, c), (b, c, a), (c, a, b)] {
                fixed.points.push(p * (2.0 / 3.0) + (q + r) * (1.0 / 6.0));
                fixed.areas.push(area / 3.0);
            }
        }
        fixed
    }

    /// The fixed area.
    pub fn area(&self) -> Real {
        self.areas.iter().sum()
    }
}

/// Why an EFG solid could not be built or solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EfgError {
    /// A parameter or material constant is out of range.
    #[error("EFG `{field}` is {value}; {message}")]
    InvalidParameter {
        /// The parameter.
        field: &'static str,
        /// Its value, briefly.
        value: String,
        /// What to use instead.
        message: &'static str,
    },
    /// The octree failed.
    #[error(transparent)]
    Octree(#[from] OctreeError),
    /// A quadrature or surface point is not covered well enough.
    #[error(transparent)]
    Cover(#[from] CoverError),
    /// A node's lumped mass is not positive.
    #[error(
        "the lumped mass of node {node} is {mass}: MLS shape functions can be negative near \
         the surface; use the consistent mass or a finer octree"
    )]
    LumpedMass {
        /// The node.
        node: usize,
        /// Its row sum.
        mass: Brief,
    },
    /// The matrices are too large to index or factor.
    #[error("the EFG matrices are too large ({nodes} nodes); use a larger cell")]
    TooLarge {
        /// Nodes.
        nodes: usize,
    },
    /// The stiffness is singular: the solid is not held.
    #[error(
        "the stiffness matrix is singular: nothing holds the solid against rigid motion; \
         fix part of its surface for a static solve"
    )]
    Singular,
    /// A load vector of the wrong length or with non-finite entries.
    #[error("the load has {got} entries (or a non-finite one); it needs 3 per node, {expected}")]
    BadLoad {
        /// Its length.
        got: usize,
        /// 3 x nodes.
        expected: usize,
    },
    /// The modal analysis failed.
    #[error(transparent)]
    Eigen(#[from] crate::linalg::eigen::EigenError),
    /// The modal basis was refused.
    #[error(transparent)]
    Modal(#[from] crate::modal::ModalError),
    /// Cancelled.
    #[error("the EFG build was cancelled")]
    Cancelled,
    /// The host refused the memory the estimate asks for, before the
    /// build allocated it ([`super::ModalSolid::build_admitted`]).
    #[error(
        "the modal solid needs about {} MB by its estimate ({} nodes, at most {} quadrature \
         points, {} modes) and {reason}; use a larger `cell` (fewer nodes), fewer \
         `modes`, or a lower `quadrature_order` or `subdivision`",
        .estimate.bytes.div_ceil(1 << 20), .estimate.nodes, .estimate.quadrature_points,
        .estimate.modes
    )]
    Refused {
        /// The estimate refused.
        estimate: Box<super::Estimate>,
        /// Why, in the host's words (what it has left, its setting).
        reason: String,
    },
}

impl EfgError {
    /// Whether the build stopped because it was cancelled, at whichever
    /// stage (octree, assembly, eigensolver) saw the flag.
    pub fn is_cancelled(&self) -> bool {
        matches!(
            self,
            Self::Cancelled
                | Self::Octree(OctreeError::Cancelled)
                | Self::Eigen(crate::linalg::eigen::EigenError::Cancelled(_))
        )
    }
}

/// An assembled EFG solid.
#[derive(Debug)]
pub struct EfgSolid {
    params: EfgParams,
    material: Material,
    octree: Octree,
    pub(super) volume: Integral,
    fixed: Option<Integral>,
    beta: Real,
    pattern: BlockPattern,
    stiffness: Vec<Real>,
    consistent_mass: Vec<Real>,
    node_masses: Vec<Real>,
    timings: Vec<(&'static str, Duration)>,
}

/// Wall times of build stages, each from the end of the one before.
#[derive(Debug)]
pub(super) struct Laps {
    clock: Instant,
    /// `(stage, time)`, in order.
    pub(super) timings: Vec<(&'static str, Duration)>,
}

impl Laps {
    /// Starts timing now, after the stages in `timings`.
    pub(super) fn after(timings: Vec<(&'static str, Duration)>) -> Self {
        Self {
            clock: Instant::now(),
            timings,
        }
    }

    /// Ends `stage` now.
    pub(super) fn lap(&mut self, stage: &'static str) {
        self.timings.push((stage, self.clock.elapsed()));
        self.clock = Instant::now();
    }
}

impl EfgSolid {
    /// Discretises `surface` (Sections 4.1.1-4.1.2) and assembles its mass
    /// and stiffness (Section 5.1) with `fixed` held by the penalty.
    ///
    /// # Errors
    /// [`EfgError`]: parameters out of range, an octree that cannot be
    /// built or has no quadrature point inside the surface
    /// ([`OctreeError::Empty`]: a solid thinner than a cell), a point not
    /// covered by enough supports, a non-positive
    /// lumped mass, matrices too large, cancellation.
    pub fn build(
        surface: &dyn ImplicitSurface,
        fixed: &FixedSurface,
        material: Material,
        params: EfgParams,
        cancel: &Cancel,
    ) -> Result<Self, EfgError> {
        Self::build_admitted(surface, fixed, material, params, cancel, &|_| Ok(()))
    }

    /// [`Self::build`], with `admit` asked once the octree stands and
    /// before anything that grows with it is allocated: the octree fixes
    /// the node count and every point's candidate supports, hence a bound
    /// on what the rest holds ([`super::Estimate`]), and `admit` may
    /// refuse it. Every loop from there on reads `cancel` per point,
    /// column or octant, so a raised flag stops the build within one of
    /// them.
    ///
    /// # Errors
    /// As [`Self::build`], and whatever `admit` returns.
    pub(super) fn build_admitted(
        surface: &dyn ImplicitSurface,
        fixed: &FixedSurface,
        material: Material,
        params: EfgParams,
        cancel: &Cancel,
        admit: &dyn Fn(&Octree) -> Result<(), EfgError>,
    ) -> Result<Self, EfgError> {
        validate(&material, &params, fixed)?;
        let cancelled = |_| EfgError::Cancelled;
        let mut laps = Laps::after(Vec::new());
        let octree = Octree::build(
            surface,
            &OctreeParams {
                cell: params.cell,
                interior_levels: params.interior_levels,
                alpha: params.alpha,
            },
            cancel,
        )?;
        laps.lap("octree");
        admit(&octree)?;
        let nodes = octree.nodes().len();
        let rule = Quadrature::build(
            &octree,
            surface,
            params.quadrature_order,
            params.subdivision,
            params.boundary_refinement,
            cancel,
        )
        .map_err(cancelled)?;
        laps.lap("quadrature");
        // A solid thinner than a cell can leave octants that the surface
        // crosses (so nodes) with no Gauss point inside it: no volume, no
        // mass, and an eigensolver shift of 0 / 0.
        if rule.points.is_empty() {
            return Err(OctreeError::Empty {
                cell: Brief(params.cell),
            }
            .into());
        }
        let table = ShapeTable::build_cancellable(&octree, params.basis, &rule.points, cancel)?;
        let volume = Integral::new(table, rule.weights, nodes);
        let fixed = if fixed.points.is_empty() {
            None
        } else {
            let table =
                ShapeTable::build_cancellable(&octree, params.basis, &fixed.points, cancel)?;
            Some(Integral::new(table, fixed.areas.clone(), nodes))
        };
        laps.lap("shape functions");
        let integrals: Vec<&Integral> = std::iter::once(&volume).chain(fixed.as_ref()).collect();
        let pattern = assemble::pattern(nodes, &integrals, cancel)
            .map_err(cancelled)?
            .ok_or(EfgError::TooLarge { nodes })?;
        let lame = assemble::lame(material.young, material.poisson);
        let beta = params.penalty * material.young / params.cell;
        // A raised flag turns the remaining columns into no-ops; the
        // check after each pass then ends the build.
        let mut stiffness = Vec::new();
        pattern.assemble(&mut stiffness, |n, out| {
            if cancel.is_cancelled() {
                return;
            }
            assemble::stiffness_column(&volume, lame, n, out);
            if let Some(fixed) = &fixed {
                assemble::product_column(fixed, beta, n, out);
            }
        });
        cancel.check().map_err(cancelled)?;
        let mut consistent_mass = Vec::new();
        pattern.assemble(&mut consistent_mass, |n, out| {
            if cancel.is_cancelled() {
                return;
            }
            assemble::product_column(&volume, material.density, n, out);
        });
        cancel.check().map_err(cancelled)?;
        let node_masses = assemble::node_masses(&volume, material.density, nodes);
        let not_positive = node_masses
            .iter()
            .enumerate()
            .find(|(_, m)| m.partial_cmp(&&0.0) != Some(std::cmp::Ordering::Greater));
        if let (MassForm::Lumped, Some((node, &mass))) = (params.mass, not_positive) {
            return Err(EfgError::LumpedMass {
                node,
                mass: Brief(mass),
            });
        }
        laps.lap("assembly");
        Ok(Self {
            params,
            material,
            octree,
            volume,
            fixed,
            beta,
            pattern,
            stiffness,
            consistent_mass,
            node_masses,
            timings: laps.timings,
        })
    }

    /// [`Self::shape_table`] reading `cancel` before each point.
    ///
    /// # Errors
    /// As [`Self::shape_table`], and [`EfgError::Cancelled`].
    pub(super) fn shape_table_cancellable(
        &self,
        points: &[Vector],
        cancel: &Cancel,
    ) -> Result<ShapeTable, EfgError> {
        ShapeTable::build_cancellable(&self.octree, self.params.basis, points, cancel)
    }

    /// Shape-function entries held for the quadrature and the fixed
    /// surface (one per point and covering node).
    pub fn shape_entries(&self) -> usize {
        self.volume.table.entries() + self.fixed.as_ref().map_or(0, |f| f.table.entries())
    }

    /// The discretisation's parameters.
    pub fn params(&self) -> &EfgParams {
        &self.params
    }

    /// The material.
    pub fn material(&self) -> &Material {
        &self.material
    }

    /// The octree.
    pub fn octree(&self) -> &Octree {
        &self.octree
    }

    /// The nodes.
    pub fn nodes(&self) -> &[Node] {
        self.octree.nodes()
    }

    /// Quadrature points in the solid.
    pub fn quadrature_points(&self) -> usize {
        self.volume.table.len()
    }

    /// The volume the quadrature integrates over.
    pub fn volume(&self) -> Real {
        self.volume.weights.iter().sum()
    }

    /// Wall time of each build stage, in order.
    pub fn timings(&self) -> &[(&'static str, Duration)] {
        &self.timings
    }

    /// The sparsity of M and K.
    pub fn pattern(&self) -> &BlockPattern {
        &self.pattern
    }

    /// K's values (with the penalty) in the pattern's order.
    pub fn stiffness(&self) -> &[Real] {
        &self.stiffness
    }

    /// The consistent M's values in the pattern's order.
    pub fn consistent_mass(&self) -> &[Real] {
        &self.consistent_mass
    }

    /// `int rho phi_I` per node: the lumped mass.
    pub fn node_masses(&self) -> &[Real] {
        &self.node_masses
    }

    /// The fixed regions' surface integral, if any.
    pub(super) fn fixed_integral(&self) -> Option<&Integral> {
        self.fixed.as_ref()
    }

    /// The penalty `beta = penalty * E / cell`: force per unit of fixed
    /// area per unit of displacement.
    pub fn penalty_stiffness(&self) -> Real {
        self.beta
    }

    /// The load of a uniform acceleration `g` (gravity), 3 per node.
    pub fn body_load(&self, g: &Vector) -> Vec<Real> {
        assemble::body_load(&self.node_masses, g)
    }

    /// Shape functions of the nodes at `points` (surface vertices,
    /// constraint points).
    ///
    /// # Errors
    /// [`CoverError`] for a point outside the solid's octree or not
    /// covered well enough.
    pub fn shape_table(&self, points: &[Vector]) -> Result<ShapeTable, CoverError> {
        ShapeTable::build(&self.octree, self.params.basis, points)
    }

    /// Nodal coefficients `u` of the static equilibrium `K u = f`.
    ///
    /// # Errors
    /// [`EfgError::BadLoad`] for a load of the wrong length or with a
    /// non-finite entry, [`EfgError::Singular`] when K is not positive
    /// definite (a free solid).
    pub fn static_displacement(&self, load: &[Real]) -> Result<Vec<Real>, EfgError> {
        let expected = 3 * self.nodes().len();
        if load.len() != expected || !load.iter().all(|f| f.is_finite()) {
            return Err(EfgError::BadLoad {
                got: load.len(),
                expected,
            });
        }
        let lame = assemble::lame(self.material.young, self.material.poisson);
        let mut solver = SparseCholesky::default();
        solver
            .solve(
                &self.pattern,
                |n, out| {
                    assemble::stiffness_column(&self.volume, lame, n, out);
                    if let Some(fixed) = &self.fixed {
                        assemble::product_column(fixed, self.beta, n, out);
                    }
                },
                load.iter().copied(),
            )
            .map(<[Real]>::to_vec)
            .ok_or(EfgError::Singular)
    }
}

fn validate(material: &Material, params: &EfgParams, fixed: &FixedSurface) -> Result<(), EfgError> {
    let invalid = |field, value: Real, message| {
        Err(EfgError::InvalidParameter {
            field,
            value: Brief(value).to_string(),
            message,
        })
    };
    let positive = |v: Real| v.is_finite() && v > 0.0;
    if !positive(material.density) {
        return invalid(
            "density",
            material.density,
            "it must be positive and finite",
        );
    }
    if !positive(material.young) {
        return invalid(
            "young",
            material.young,
            "Young's modulus must be positive and finite",
        );
    }
    if !(material.poisson.is_finite() && (0.0..0.5).contains(&material.poisson)) {
        return invalid(
            "poisson",
            material.poisson,
            "Poisson's ratio must lie in [0, 0.5): 0.5 is incompressible, which a \
             displacement formulation locks on; use 0.49 at most",
        );
    }
    if !(1..=MAX_ORDER).contains(&params.quadrature_order) {
        return invalid(
            "quadrature_order",
            params.quadrature_order as Real,
            "use 1 to 5 Gauss points per axis",
        );
    }
    if !(1..=8).contains(&params.subdivision) {
        return invalid(
            "subdivision",
            params.subdivision as Real,
            "use 1 to 8 integration cells per octant axis",
        );
    }
    if !(1..=4).contains(&params.boundary_refinement) {
        return invalid(
            "boundary_refinement",
            params.boundary_refinement as Real,
            "use 1 to 4: boundary octants are cut that many times finer",
        );
    }
    if !positive(params.penalty) {
        return invalid(
            "penalty",
            params.penalty,
            "it must be positive and finite; 1e4 is the default",
        );
    }
    if fixed.points.len() != fixed.areas.len()
        || !fixed.points.iter().all(|p| p.iter().all(|v| v.is_finite()))
        || !fixed.areas.iter().all(|a| a.is_finite() && *a >= 0.0)
    {
        return invalid(
            "fixed",
            fixed.points.len() as Real,
            "fixed points need one finite, non-negative area each",
        );
    }
    Ok(())
}
