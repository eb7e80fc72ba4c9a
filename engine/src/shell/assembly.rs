//! What the static, vibration and dynamic routes share: loads, supports,
//! grabs, internal forces, and the assembly of the tangent and mass over
//! one sparse pattern. A grab is a support whose held value is not zero
//! (the target's offset from the reference), three springs of a given
//! stiffness, one per axis.
//!
//! **Supports are penalties.** A support holds a linear functional of the
//! displacement at zero: the displacement along a direction, or the slope
//! of the normal displacement across a boundary (a clamp's rotation). Each
//! adds `1/2 alpha L (c . u)^2` for the boundary length `L` its point
//! stands for. Why penalties rather than multipliers: the tangent stays
//! positive definite (one Cholesky, no saddle point) and the pattern is
//! the stiffness's own, and MLS shape functions do not interpolate, so a
//! support cannot be set on a node anyway. The stiffness is scaled with
//! the cell `h` on the surface so that the penalty keeps pace with the
//! shell as it refines: `beta D / h^3` for a normal displacement (bending
//! carries it), `beta E t / ((1 - nu^2) h)` for a tangential one
//! (membrane), blended by the direction's angle to the normal, and
//! `beta D / h` for a slope; `beta = 10` by default (on the clamped plate
//! of `engine/tests/plate.rs` at 16 cells, 1 lets it sag 48 % further and
//! 100 6 % less: too weak a penalty frees the edge, too strong a one
//! stiffens the approximation beside it).

use super::error::ShellError;
use super::kirchhoff::{LOCAL, LocalGradient, LocalHessian, SLOTS, gradient_hessian};
use super::model::{ShellModel, Stencil, SurfacePoint};
use crate::approx::gauss::gauss_legendre;
use crate::geometry::quadtree::Point2;
use crate::linalg::sparse::{BlockColumn, BlockPattern};
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// What a support holds at zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SupportKind {
    /// The displacement along this unit direction.
    Displacement(Vector),
    /// The slope of the normal displacement across this unit parametric
    /// direction (with zero displacement, a clamp).
    Slope(Point2),
}

/// A support at one point of the parametric domain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Support {
    /// Where.
    pub at: Point2,
    /// The length of boundary on the surface it stands for.
    pub length: Real,
    /// What it holds.
    pub kind: SupportKind,
}

/// A grab (Guo–Qin 5.3.3's, as a penalty): with a `target`, springs of
/// `stiffness` (force per length) pulling the surface's point at `at`
/// there, and with a `rotation`, turning the surface there by it: its tangents `a_alpha`
/// (and so its director, their normalised cross product) held at `R
/// A_alpha`, by springs of `stiffness s^2` on the tangents (`s` the
/// point's leaf side in the parametric domain, so that a tangent's
/// change across the leaf costs what the same change of position does).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grab {
    /// Where, in the parametric domain.
    pub at: Point2,
    /// Where the point is pulled, if held in place.
    pub target: Option<Vector>,
    /// The rotation vector (axis times angle, rad) the surface at the
    /// point is turned by from its rest orientation, if held.
    pub rotation: Option<Vector>,
    /// Spring stiffness.
    pub stiffness: Real,
}

/// Where a grab's springs sit among the constraints, and the rest
/// geometry their held values are measured from.
#[derive(Debug, Clone)]
struct GrabHold {
    /// The reference surface's point.
    rest: Vector,
    /// Its tangents `A_1`, `A_2`.
    tangents: [Vector; 2],
    /// Its first constraint.
    first: usize,
    /// Whether its position is held (three springs first).
    placed: bool,
    /// Whether its tangents are held (six springs after those).
    turned: bool,
}

impl GrabHold {
    /// Each spring's shape-function row (0: `N`, 1 and 2: `N_,alpha`),
    /// axis and held value: the position's offset per axis, then each
    /// held tangent's, `(R A_alpha - A_alpha) . e_axis`.
    fn springs(
        &self,
        target: Option<Vector>,
        rotation: Option<Vector>,
    ) -> Vec<(usize, usize, Real)> {
        let mut out = Vec::with_capacity(9);
        if let Some(target) = target {
            out.extend((0..3).map(|k| (0, k, target[k] - self.rest[k])));
        }
        if let Some(r) = rotation {
            let turn = nalgebra::Rotation3::new(r);
            for (alpha, t) in self.tangents.iter().enumerate() {
                let moved = turn * t - t;
                out.extend((0..3).map(|k| (alpha + 1, k, moved[k])));
            }
        }
        out
    }
}

/// Loads on a shell, in the reference configuration (dead loads).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Load {
    /// Force per unit reference area (self weight: `rho t g`).
    pub per_area: Vector,
    /// Pressure on the reference normal's side, per unit reference area.
    pub pressure: Real,
    /// Point forces at points of the parametric domain.
    pub points: Vec<(Point2, Vector)>,
    /// Whether the surface is closed, so that the pressure has no net
    /// force: its quadrature over the fitted surface leaves a small one
    /// (1.2e-3 of `p pi R^2` on a unit sphere at cells of 0.2, in
    /// `engine/tests/shells.rs`; enough to push a free ball away), which
    /// is then taken off, spread over the nodes by their areas.
    pub closed: bool,
}

/// A support as the assembly reads it: `1/2 stiffness (sum_I c_I u_I .
/// direction)^2`.
#[derive(Debug, Clone)]
pub(super) struct Constraint {
    stencil: Stencil,
    coefficients: Vec<Real>,
    direction: Vector,
    stiffness: Real,
    /// The value held: zero for a support, a grab's target offset.
    offset: Real,
}

impl Constraint {
    /// Its spring's stiffness.
    pub(super) fn stiffness(&self) -> Real {
        self.stiffness
    }

    /// Adds `scale` times its functional's gradient, `c_I direction` at
    /// each node `I` of its stencil, to `out`.
    pub(super) fn add_gradient(&self, scale: Real, out: &mut [Vector]) {
        let force = scale * self.direction;
        for (&k, c) in self.stencil.nodes.iter().zip(&self.coefficients) {
            out[k as usize] += *c * force;
        }
    }

    /// `sum_I c_I u_I . direction` (the held value not subtracted).
    pub(super) fn value(&self, u: &[Vector]) -> Real {
        self.stencil
            .nodes
            .iter()
            .zip(&self.coefficients)
            .map(|(&k, c)| c * u[k as usize].dot(&self.direction))
            .sum()
    }
}

impl ShellModel {
    /// Supports of `kinds` at 4-point Gauss rules on `pieces` equal pieces
    /// of the parametric segment `from -> to`, each weighted by the
    /// surface length it stands for.
    ///
    /// # Errors
    /// [`ShellError`] where a point of the segment lies outside the chart
    /// or its supports cannot carry the basis.
    pub fn edge_supports(
        &self,
        from: Point2,
        to: Point2,
        pieces: usize,
        kinds: &[SupportKind],
    ) -> Result<Vec<Support>, ShellError> {
        let (x, w) = gauss_legendre(4);
        let d = [to[0] - from[0], to[1] - from[1]];
        let mut out = Vec::new();
        for piece in 0..pieces {
            for (xa, wa) in x.iter().zip(w) {
                let s = (piece as Real + 0.5 * (1.0 + xa)) / pieces as Real;
                let at = [from[0] + s * d[0], from[1] + s * d[1]];
                let q = self.stencil(at)?.local(self.reference());
                let tangent = d[0] * q[0] + d[1] * q[1];
                let length = 0.5 * wa * tangent.norm() / pieces as Real;
                out.extend(kinds.iter().map(|&kind| Support { at, length, kind }));
            }
        }
        Ok(out)
    }

    /// The interpolated displacement at `u` for nodal coefficients
    /// `displacement`.
    ///
    /// # Errors
    /// As [`ShellModel::stencil`].
    pub fn displacement_at(
        &self,
        u: Point2,
        displacement: &[Vector],
    ) -> Result<Vector, ShellError> {
        Ok(self.stencil(u)?.value(displacement))
    }

    /// The nodal load vector of `load`.
    ///
    /// # Errors
    /// As [`ShellModel::stencil`], for a point load off the chart.
    pub fn load_vector(&self, load: &Load) -> Result<Vec<Vector>, ShellError> {
        let mut f = vec![Vector::zeros(); self.node_count()];
        let mut areas = vec![0.0; self.node_count()];
        let mut net = Vector::zeros();
        for p in self.points() {
            let r = &p.reference;
            let area = p.weight * r.area;
            let per_area = (load.per_area + load.pressure * r.normal) * area;
            net += load.pressure * r.normal * area;
            for (&k, row) in p.stencil.nodes.iter().zip(&p.stencil.rows) {
                f[k as usize] += row[0] * per_area;
                areas[k as usize] += row[0] * area;
            }
        }
        if load.closed {
            let total: Real = areas.iter().sum();
            if total > 0.0 {
                for (fk, a) in f.iter_mut().zip(&areas) {
                    *fk -= net * (a / total);
                }
            }
        }
        for (at, force) in &load.points {
            let s = self.stencil(*at)?;
            for (&k, row) in s.nodes.iter().zip(&s.rows) {
                f[k as usize] += row[0] * force;
            }
        }
        Ok(f)
    }

    pub(super) fn constraint(
        &self,
        support: &Support,
        beta: Real,
    ) -> Result<Constraint, ShellError> {
        let stencil = self.stencil(support.at)?;
        let q = stencil.local(self.reference());
        let area = q[0].cross(&q[1]);
        let normal = area.normalize();
        let leaf = self
            .tree()
            .leaf_of(support.at)
            .ok_or(ShellError::Outside { at: support.at })?;
        let (_, side) = self.tree().bounds(self.tree().leaves()[leaf]);
        let h = side * area.norm().sqrt();
        let m = self.material();
        let (bending, membrane) = (m.bending_stiffness(), m.membrane_stiffness());
        let (coefficients, direction, stiffness) = match support.kind {
            SupportKind::Displacement(e) => {
                let e = e.try_normalize(0.0).ok_or(ShellError::Parameter {
                    what: "support direction",
                    got: 0.0,
                    range: "a non-zero vector",
                })?;
                let cos2 = e.dot(&normal).powi(2);
                let alpha = cos2 * bending / h.powi(3) + (1.0 - cos2) * membrane / h;
                let c = stencil.rows.iter().map(|r| r[0]).collect();
                (c, e, alpha)
            }
            SupportKind::Slope(d) => {
                let along = (d[0] * q[0] + d[1] * q[1]).norm();
                if !along.is_finite() || along <= 0.0 {
                    return Err(ShellError::Parameter {
                        what: "slope direction",
                        got: 0.0,
                        range: "a non-zero parametric direction",
                    });
                }
                let c = stencil
                    .rows
                    .iter()
                    .map(|r| (d[0] * r[1] + d[1] * r[2]) / along)
                    .collect();
                (c, normal, bending / h)
            }
        };
        Ok(Constraint {
            stencil,
            coefficients,
            direction,
            stiffness: beta * stiffness * support.length,
            offset: 0.0,
        })
    }

    /// A grab's springs (three on the position, one per axis, with a
    /// target; six on the tangents with a rotation), and where it holds.
    fn grab_constraints(&self, grab: &Grab) -> Result<(Vec<Constraint>, GrabHold), ShellError> {
        if !(grab.stiffness > 0.0 && grab.stiffness.is_finite()) {
            return Err(ShellError::Parameter {
                what: "grab stiffness",
                got: grab.stiffness,
                range: "a finite value > 0 (force per length)",
            });
        }
        let finite = |v: &Vector| v.iter().all(|c| c.is_finite());
        if grab.target.is_none() && grab.rotation.is_none() {
            return Err(ShellError::Parameter {
                what: "grab",
                got: 0.0,
                range: "a target, a rotation or both",
            });
        }
        if !grab.target.as_ref().is_none_or(finite) || !grab.rotation.as_ref().is_none_or(finite) {
            return Err(ShellError::Parameter {
                what: "grab target",
                got: Real::NAN,
                range: "a finite point and rotation",
            });
        }
        let stencil = self.stencil(grab.at)?;
        let q = stencil.local(self.reference());
        let hold = GrabHold {
            rest: stencil.value(self.reference()),
            tangents: [q[0], q[1]],
            first: 0,
            placed: grab.target.is_some(),
            turned: grab.rotation.is_some(),
        };
        let leaf = self
            .tree()
            .leaf_of(grab.at)
            .ok_or(ShellError::Outside { at: grab.at })?;
        let (_, side) = self.tree().bounds(self.tree().leaves()[leaf]);
        let springs = hold
            .springs(grab.target, grab.rotation)
            .into_iter()
            .map(|(row, axis, offset)| Constraint {
                stencil: stencil.clone(),
                coefficients: stencil.rows.iter().map(|r| r[row]).collect(),
                direction: Vector::ith(axis, 1.0),
                stiffness: match row {
                    0 => grab.stiffness,
                    _ => grab.stiffness * side * side,
                },
                offset,
            })
            .collect();
        Ok((springs, hold))
    }

    /// The internal forces `dU/du_I` at nodal displacements `u`, and the
    /// strain energy `U`.
    ///
    /// # Errors
    /// [`ShellError::Folded`] where the surface folds flat.
    pub fn internal_forces(&self, u: &[Vector]) -> Result<(Vec<Vector>, Real), ShellError> {
        let mut local = vec![([0.0; LOCAL], [[0.0; LOCAL]; LOCAL]); self.points().len()];
        self.evaluate(u, &mut local)
    }

    /// [`Self::internal_forces`], with each point's energy gradient and
    /// Hessian left in `local`.
    pub(super) fn evaluate(
        &self,
        u: &[Vector],
        local: &mut [(LocalGradient, LocalHessian)],
    ) -> Result<(Vec<Vector>, Real), ShellError> {
        let x: Vec<Vector> = self.reference().iter().zip(u).map(|(a, b)| a + b).collect();
        let thickness = self.material().thickness;
        let points = self.points();
        let energy = local
            .par_iter_mut()
            .zip(points)
            .map(|((g, h), p)| {
                let q = p.stencil.local(&x);
                gradient_hessian(&p.reference, thickness, &q, g, h)
                    .map(|w| w * p.weight * p.reference.area)
                    .ok_or(ShellError::Folded { at: p.at })
            })
            .try_reduce(|| 0.0, |a, b| Ok(a + b))?;
        let mut f = vec![Vector::zeros(); u.len()];
        for (p, (g, _)) in points.iter().zip(local.iter()) {
            let w = p.weight * p.reference.area;
            for (&k, row) in p.stencil.nodes.iter().zip(&p.stencil.rows) {
                let fk = &mut f[k as usize];
                for s in 0..SLOTS {
                    let c = w * row[s + 1];
                    for comp in 0..3 {
                        fk[comp] += c * g[3 * s + comp];
                    }
                }
            }
        }
        Ok((f, energy))
    }
}

/// Where the grabs' springs go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum GrabBlocks {
    /// Into the sparse pattern and the assembled matrices, beside the
    /// shell's own blocks: the nonlinear route assembles its tangent
    /// anew every iteration anyway.
    InPattern,
    /// Kept out of them: the linear route adds them to its constant `K`
    /// as a low-rank term, so that grabbing and letting go assemble and
    /// factorise nothing.
    Apart,
}

/// One shell's sparse assembly with its supports: the pattern over every
/// stencil, the items (quadrature points, then supports) each node is
/// in, and each point's energy gradient and Hessian at the last
/// evaluation.
#[derive(Debug, Clone)]
pub(super) struct Assembly {
    pub(super) pattern: BlockPattern,
    /// How many of `constraints` are supports (the grabs' follow).
    supports: usize,
    grab_blocks: GrabBlocks,
    /// Per node, the items it is in: `(item, a, start)`, the node being
    /// the item's `a`-th, `slots[start + b - a]` the place in its block
    /// column of the item's `b`-th node, for every `b >= a` (found once
    /// here, not by a search per pair and assembly).
    touching: Vec<Vec<(u32, u32, u32)>>,
    slots: Vec<u32>,
    /// The supports' penalties, then three springs per grab.
    constraints: Vec<Constraint>,
    /// Each grab's springs and rest geometry.
    grab_rest: Vec<GrabHold>,
    local: Vec<(LocalGradient, LocalHessian)>,
    /// The norm of the supports' and grabs' forces at the last
    /// [`Self::forces`]: a force scale where they balance the shell.
    spring_norm: Real,
}

impl Assembly {
    /// The assembly of `model` held by `supports` with penalty scale
    /// `beta`, and pulled by `grabs`, whose springs go as `grab_blocks`
    /// says.
    pub(super) fn new(
        model: &ShellModel,
        supports: &[Support],
        grabs: &[Grab],
        beta: Real,
        grab_blocks: GrabBlocks,
    ) -> Result<Self, ShellError> {
        if !(beta > 0.0 && beta.is_finite()) {
            return Err(ShellError::Parameter {
                what: "penalty",
                got: beta,
                range: "a finite value > 0",
            });
        }
        let mut constraints = supports
            .iter()
            .map(|s| model.constraint(s, beta))
            .collect::<Result<Vec<_>, _>>()?;
        let supports = constraints.len();
        let (springs, grab_rest) = grab_springs(model, grabs, supports)?;
        constraints.extend(springs);
        let patterned = match grab_blocks {
            GrabBlocks::InPattern => &constraints[..],
            GrabBlocks::Apart => &constraints[..supports],
        };
        let points = model.points();
        let stencils = || {
            points
                .iter()
                .map(|p| &p.stencil)
                .chain(patterned.iter().map(|c| &c.stencil))
        };
        let (pattern, columns) = model.pattern(stencils())?;
        let mut touching: Vec<Vec<(u32, u32, u32)>> = vec![Vec::new(); model.node_count()];
        let mut slots = Vec::new();
        for (item, s) in stencils().enumerate() {
            for (a, &n) in s.nodes.iter().enumerate() {
                let start = u32::try_from(slots.len()).map_err(|_| ShellError::TooLarge {
                    nodes: model.node_count(),
                })?;
                touching[n as usize].push((item as u32, a as u32, start));
                let rows = &columns[n as usize];
                for m in &s.nodes[a..] {
                    // Every pair of a stencil is in the pattern (built from
                    // these stencils).
                    let slot = rows.binary_search(m).map_err(|_| ShellError::TooLarge {
                        nodes: model.node_count(),
                    })?;
                    slots.push(slot as u32);
                }
            }
        }
        let local = vec![([0.0; LOCAL], [[0.0; LOCAL]; LOCAL]); points.len()];
        Ok(Self {
            pattern,
            supports,
            grab_blocks,
            touching,
            slots,
            constraints,
            grab_rest,
            local,
            spring_norm: 0.0,
        })
    }

    /// Replaces the grabs of an assembly built with
    /// [`GrabBlocks::Apart`] (one whose pattern holds its grabs is built
    /// anew instead): nothing else changes.
    ///
    /// # Errors
    /// [`ShellError`] for a grab off the chart, a stiffness out of range
    /// or a target not finite; the grabs are then as they were.
    pub(super) fn replace_grabs(
        &mut self,
        model: &ShellModel,
        grabs: &[Grab],
    ) -> Result<(), ShellError> {
        debug_assert_eq!(self.grab_blocks, GrabBlocks::Apart);
        let (springs, grab_rest) = grab_springs(model, grabs, self.supports)?;
        self.constraints.truncate(self.supports);
        self.constraints.extend(springs);
        self.grab_rest = grab_rest;
        Ok(())
    }

    /// The grabs' springs, in the order they were given, each grab's
    /// consecutive.
    pub(super) fn grab_springs(&self) -> &[Constraint] {
        &self.constraints[self.supports..]
    }

    /// The internal and support forces at nodal displacements `u`, and
    /// the strain energy (supports' included); keeps each point's
    /// Hessian for [`Self::column`].
    pub(super) fn forces(
        &mut self,
        model: &ShellModel,
        u: &[Vector],
    ) -> Result<(Vec<Vector>, Real), ShellError> {
        let (mut f, mut energy) = model.evaluate(u, &mut self.local)?;
        let mut springs = vec![Vector::zeros(); f.len()];
        for c in &self.constraints {
            let value = c.value(u) - c.offset;
            energy += 0.5 * c.stiffness * value * value;
            c.add_gradient(c.stiffness * value, &mut springs);
        }
        self.spring_norm = springs
            .iter()
            .map(|v| v.norm_squared())
            .sum::<Real>()
            .sqrt();
        for (fk, sk) in f.iter_mut().zip(&springs) {
            *fk += sk;
        }
        Ok((f, energy))
    }

    /// Block column `node` of `stiffness K + mass M`: `K` the tangent at
    /// the last [`Self::forces`] with the supports' penalties, scaled by
    /// `stiffness`; `M` the consistent mass.
    pub(super) fn column(
        &self,
        model: &ShellModel,
        node: usize,
        column: &mut BlockColumn<'_>,
        stiffness: Real,
        mass: Real,
    ) {
        let points = model.points();
        let areal_mass = model.material().density * model.material().thickness;
        for &(item, a, start) in &self.touching[node] {
            let (item, a) = (item as usize, a as usize);
            let slots = &self.slots[start as usize..];
            if let Some(p) = points.get(item) {
                let w = p.weight * p.reference.area;
                let scales = (stiffness * w, mass * areal_mass * w);
                add_point_block(column, p, &self.local[item].1, a, scales, slots);
            } else if stiffness != 0.0 {
                let c = &self.constraints[item - points.len()];
                let ca = stiffness * c.stiffness * c.coefficients[a];
                let e = &c.direction;
                let rest = c.coefficients.iter().skip(a).zip(slots);
                for (cb, &slot) in rest {
                    let slot = slot as usize;
                    for alpha in 0..3 {
                        for beta in 0..3 {
                            column.add(slot, alpha, beta, ca * cb * e[alpha] * e[beta]);
                        }
                    }
                }
            }
        }
    }
}

impl Assembly {
    /// `(stiffness K + mass M) v`, matrix-free: `K` the tangent at the last
    /// [`Self::forces`] with the supports' penalties, `M` the consistent
    /// mass.
    pub(super) fn product(
        &self,
        model: &ShellModel,
        v: &[Vector],
        stiffness: Real,
        mass: Real,
    ) -> Vec<Vector> {
        let areal_mass = model.material().density * model.material().thickness;
        let mut out = vec![Vector::zeros(); v.len()];
        for (p, (_, hess)) in model.points().iter().zip(&self.local) {
            let w = p.weight * p.reference.area;
            let s = &p.stencil;
            if stiffness != 0.0 {
                let q = s.local(v);
                let mut hq = [0.0; LOCAL];
                for (r, hr) in hq.iter_mut().zip(hess) {
                    *r = (0..LOCAL).map(|c| hr[c] * q[c / 3][c % 3]).sum::<Real>() * stiffness * w;
                }
                for (&k, row) in s.nodes.iter().zip(&s.rows) {
                    let ok = &mut out[k as usize];
                    for slot in 0..SLOTS {
                        for comp in 0..3 {
                            ok[comp] += row[slot + 1] * hq[3 * slot + comp];
                        }
                    }
                }
            }
            if mass != 0.0 {
                let value = s.value(v) * (mass * areal_mass * w);
                for (&k, row) in s.nodes.iter().zip(&s.rows) {
                    out[k as usize] += row[0] * value;
                }
            }
        }
        if stiffness != 0.0 {
            for c in &self.constraints {
                c.add_gradient(stiffness * c.stiffness * c.value(v), &mut out);
            }
        }
        out
    }
}

impl Assembly {
    /// The supports' and grabs' forces at zero displacement (their
    /// springs pulling towards the held values) and their energy there:
    /// what a linear shell adds to `K u`.
    pub(super) fn springs_at_rest(&self, nodes: usize) -> (Vec<Vector>, Real) {
        let mut f = vec![Vector::zeros(); nodes];
        let mut energy = 0.0;
        for c in &self.constraints {
            energy += 0.5 * c.stiffness * c.offset * c.offset;
            c.add_gradient(-c.stiffness * c.offset, &mut f);
        }
        (f, energy)
    }

    /// See `spring_norm`.
    pub(super) fn spring_force_norm(&self) -> Real {
        self.spring_norm
    }

    /// Moves grab `index`'s target and turns it to `rotation`; `false`
    /// when there is no such grab, or it was set holding other things (a
    /// target or a rotation given where it held none, or left out where
    /// it held one).
    pub(super) fn move_grab(
        &mut self,
        index: usize,
        target: Option<Vector>,
        rotation: Option<Vector>,
    ) -> bool {
        let Some(hold) = self.grab_rest.get(index) else {
            return false;
        };
        if hold.placed != target.is_some() || hold.turned != rotation.is_some() {
            return false;
        }
        let springs = hold.springs(target, rotation);
        for (c, (_, _, offset)) in self.constraints[hold.first..].iter_mut().zip(springs) {
            c.offset = offset;
        }
        true
    }
}

/// The springs of `grabs` in order, and each grab's hold, numbered as
/// constraints from `first`.
fn grab_springs(
    model: &ShellModel,
    grabs: &[Grab],
    first: usize,
) -> Result<(Vec<Constraint>, Vec<GrabHold>), ShellError> {
    let mut springs = Vec::new();
    let mut holds = Vec::with_capacity(grabs.len());
    for grab in grabs {
        let (more, mut hold) = model.grab_constraints(grab)?;
        hold.first = first + springs.len();
        springs.extend(more);
        holds.push(hold);
    }
    Ok((springs, holds))
}

/// Adds a point's energy Hessian `hess` mapped to the nodes and its
/// consistent mass, scaled by `(stiffness, mass)`, to the column of its
/// node `a`; `slots[b - a]` is node `b`'s place in that column.
fn add_point_block(
    column: &mut BlockColumn<'_>,
    p: &SurfacePoint,
    hess: &LocalHessian,
    a: usize,
    (stiffness, mass): (Real, Real),
    slots: &[u32],
) {
    let ra = &p.stencil.rows[a];
    // t[alpha][j] = sum_s N_a,s H[3 s + alpha][j].
    let mut t = [[0.0; LOCAL]; 3];
    if stiffness != 0.0 {
        for s in 0..SLOTS {
            let c = stiffness * ra[s + 1];
            if c == 0.0 {
                continue;
            }
            for (alpha, row) in t.iter_mut().enumerate() {
                for (tj, hj) in row.iter_mut().zip(&hess[3 * s + alpha]) {
                    *tj += c * hj;
                }
            }
        }
    }
    let ma = mass * ra[0];
    for (rb, &slot) in p.stencil.rows[a..].iter().zip(slots) {
        let slot = slot as usize;
        for (alpha, row) in t.iter().enumerate() {
            for beta in 0..3 {
                let mut v: Real = (0..SLOTS).map(|s| rb[s + 1] * row[3 * s + beta]).sum();
                if alpha == beta {
                    v += ma * rb[0];
                }
                column.add(slot, alpha, beta, v);
            }
        }
    }
}
