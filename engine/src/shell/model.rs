//! A shell's discretisation on one chart: the quadtree's nodes, the MLS
//! shape functions with their first and second derivatives at every
//! quadrature point (a [`Stencil`] each), and the reference middle
//! surface.
//!
//! **The surface is carried by the nodes.** The reference surface is not
//! read from the input at the quadrature points but fitted: nodal
//! positions `X_I` minimising `int |sum_I N_I X_I - x(u)|^2 du` (an L2
//! projection, one sparse Cholesky), and the deformed surface is
//! `sum_I N_I (X_I + u_I)`. Reference and deformed surfaces are then the
//! same kind of function, so a rigid motion of the nodes strains nothing
//! exactly (the patch test), and a surface the basis spans (a plane, a
//! paraboloid under the quadratic basis) is reproduced exactly. The cost
//! is a small geometric error where it does not (a cylinder's arc), which
//! shrinks with the cells.

use super::error::ShellError;
use super::kirchhoff::{Local, Reference};
use crate::approx::mls::{Mls, MlsParams, Order, ShapeHessians};
use crate::approx::tensor::{WeightHessian, tensor_weight_hessian};
use crate::cancel::Cancel;
use crate::geometry::atlas::Transfer;
use crate::geometry::quadtree::{ChartDomain, Point2, Quadtree, QuadtreeParams};
use crate::linalg::sparse::{BlockPattern, SparseCholesky};
use crate::math::{Real, Vector};
use nalgebra::{Matrix2, Vector2};
use rayon::prelude::*;

/// A chart whose domain is a patch of a shell's reference middle surface.
pub trait ShellSurface: ChartDomain + Sync {
    /// The reference surface's point at `u` (inside the domain).
    fn position(&self, u: Point2) -> Vector;

    /// Where the point `u` also lies in the other charts of an atlas
    /// (see [`crate::geometry::atlas::Atlas::transfers`]): a node there
    /// reaches across the seam through them. None for a single chart.
    fn transfers(&self, _u: Point2) -> Vec<Transfer> {
        Vec::new()
    }
}

/// A shell's material: thickness, density, Young's modulus and Poisson's
/// ratio (consistent units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Thickness `t`.
    pub thickness: Real,
    /// Mass per unit volume.
    pub density: Real,
    /// Young's modulus `E`.
    pub young: Real,
    /// Poisson's ratio `nu`, in `[0, 0.5)`.
    pub poisson: Real,
}

impl Material {
    /// Bending stiffness `D = E t^3 / (12 (1 - nu^2))`.
    pub fn bending_stiffness(&self) -> Real {
        self.young * self.thickness.powi(3) / (12.0 * (1.0 - self.poisson * self.poisson))
    }

    /// Membrane stiffness `E t / (1 - nu^2)`.
    pub fn membrane_stiffness(&self) -> Real {
        self.young * self.thickness / (1.0 - self.poisson * self.poisson)
    }

    fn validate(&self) -> Result<(), ShellError> {
        let positive = |what, got: Real| {
            if got > 0.0 && got.is_finite() {
                Ok(())
            } else {
                Err(ShellError::Parameter {
                    what,
                    got,
                    range: "a finite value > 0",
                })
            }
        };
        positive("thickness", self.thickness)?;
        positive("young", self.young)?;
        if !(self.density >= 0.0 && self.density.is_finite()) {
            return Err(ShellError::Parameter {
                what: "density",
                got: self.density,
                range: "a finite value >= 0",
            });
        }
        if !(0.0..0.5).contains(&self.poisson) {
            return Err(ShellError::Parameter {
                what: "poisson",
                got: self.poisson,
                range: "0 <= nu < 0.5 (plane stress in the shell's surface)",
            });
        }
        Ok(())
    }
}

/// How a shell is discretised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShellParams {
    /// The MLS basis: bending needs second derivatives that reproduce a
    /// constant curvature, so [`Order::Quadratic`] unless only membranes
    /// matter.
    pub order: Order,
    /// The quadtree: resolution, support size `eta`, quadrature.
    pub quadtree: QuadtreeParams,
}

impl ShellParams {
    /// Cells of `resolution` on the surface, the quadratic basis, one
    /// ring of exterior leaves and supports of `eta = 4` cells: a
    /// quadratic fit needs three nodes along each axis over every point,
    /// the domain's corners included.
    pub fn new(resolution: Real) -> Self {
        Self {
            order: Order::Quadratic,
            quadtree: QuadtreeParams {
                eta: 4.0,
                exterior: 1,
                ..QuadtreeParams::new(resolution)
            },
        }
    }
}

/// One shape function's value and derivatives at a point:
/// `N, N_,1, N_,2, N_,11, N_,22, N_,12`.
pub type ShapeRow = [Real; 6];

/// The nodes whose supports hold a point, with their shape functions
/// there.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stencil {
    /// Node indices, ascending.
    pub nodes: Vec<u32>,
    /// Each node's [`ShapeRow`].
    pub rows: Vec<ShapeRow>,
}

impl Stencil {
    /// The surface's local unknowns at this point (`x_,1`, `x_,2`,
    /// `x_,11`, `x_,22`, `x_,12`) for nodal values `x`.
    pub fn local(&self, x: &[Vector]) -> Local {
        let mut q = [Vector::zeros(); 5];
        for (&k, row) in self.nodes.iter().zip(&self.rows) {
            let xk = &x[k as usize];
            for (s, qs) in q.iter_mut().enumerate() {
                *qs += row[s + 1] * xk;
            }
        }
        q
    }

    /// The interpolated value `sum_I N_I x_I`.
    pub fn value(&self, x: &[Vector]) -> Vector {
        self.nodes
            .iter()
            .zip(&self.rows)
            .map(|(&k, row)| row[0] * x[k as usize])
            .sum()
    }
}

/// A quadrature point of the middle surface.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfacePoint {
    /// Where, in the parametric domain.
    pub at: Point2,
    /// Parametric area it stands for; the reference area is
    /// `weight * reference.area`.
    pub weight: Real,
    /// Its shape functions.
    pub stencil: Stencil,
    /// The reference surface there.
    pub reference: Reference,
}

/// A shell discretised on one chart (see the module's documentation).
#[derive(Debug, Clone)]
pub struct ShellModel {
    tree: Quadtree,
    material: Material,
    order: Order,
    /// Nodes in the parametric plane, as 3-vectors with zero `z` (the MLS
    /// routines' points).
    nodes: Vec<Vector>,
    /// Half the side of each node's support.
    half: Vec<Real>,
    /// Each quadtree node's index among `nodes`, or `u32::MAX` for a node
    /// dropped because its support holds no quadrature point (an
    /// exterior leaf's beyond a curved boundary: it would carry nothing,
    /// and leave the projection singular).
    of_tree: Vec<u32>,
    /// Reference nodal positions `X_I`.
    reference: Vec<Vector>,
    points: Vec<SurfacePoint>,
    /// Nodes seen across a seam from a neighbouring chart, by their
    /// first coordinate there (empty on a single chart).
    ghosts: Vec<Ghost>,
    /// The largest of the ghosts' `reach`.
    ghost_reach: Real,
}

/// A node of one chart in a neighbouring chart's place, across a seam
/// (Guo–Qin Fig. 8c): its support, a square in its own chart, is carried
/// over by the transition's Jacobian, so the node's weight is the same
/// function of the surface seen from either side (to the transition's
/// first order).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ghost {
    /// The node, numbered as the quadtree numbers it.
    tree_node: u32,
    /// Where it lies in the neighbour's place.
    at: Point2,
    /// `d (own chart) / d (neighbour's chart)` at it.
    jacobian: Matrix2<Real>,
    /// Its support's half side, in its own chart.
    half: Real,
    /// Half the side of the box its support covers in the neighbour's
    /// place.
    reach: Real,
}

impl Ghost {
    /// A step `d` in the neighbour's place, in the node's own chart.
    fn own(&self, d: [Real; 2]) -> Vector2<Real> {
        self.jacobian * Vector2::new(d[0], d[1])
    }

    /// Whether its support covers the point `u` of the neighbour's place.
    fn covers(&self, u: Point2) -> bool {
        let e = self.own([u[0] - self.at[0], u[1] - self.at[1]]);
        e[0].abs() < self.half && e[1].abs() < self.half
    }

    /// Its weight at the offset `d = x - at` of the neighbour's place,
    /// with the gradient and Hessian there: the square weight in its own
    /// chart by the chain rule (`J^T g`, `J^T H J`).
    fn weight(&self, d: &[Real; 3]) -> Option<WeightHessian> {
        let e = self.own([d[0], d[1]]);
        let (w, g, h) = tensor_weight_hessian(2, &[e[0], e[1], 0.0], &[self.half; 3])?;
        let j = &self.jacobian;
        let gradient = j.transpose() * Vector2::new(g[0], g[1]);
        let hessian = j.transpose() * Matrix2::new(h[0][0], h[0][1], h[1][0], h[1][1]) * j;
        Some((
            w,
            [gradient[0], gradient[1], 0.0],
            [
                [hessian[(0, 0)], hessian[(0, 1)], 0.0],
                [hessian[(1, 0)], hessian[(1, 1)], 0.0],
                [0.0; 3],
            ],
        ))
    }
}

/// The nodes of `tree` that other charts of `surface` hold, in those
/// charts' places, by their first coordinate there.
fn ghosts_of(surface: &impl ShellSurface, tree: &Quadtree) -> Vec<Ghost> {
    let mut ghosts: Vec<Ghost> = (0..tree.leaves().len())
        .into_par_iter()
        .flat_map_iter(|k| {
            let half = tree.half_width(k);
            surface
                .transfers(tree.node(k))
                .into_iter()
                .filter_map(move |t| {
                    let inverse = t.jacobian.try_inverse()?;
                    let spread = (0..2)
                        .map(|r| inverse[(r, 0)].abs() + inverse[(r, 1)].abs())
                        .fold(0.0, Real::max);
                    Some(Ghost {
                        tree_node: k as u32,
                        at: t.at,
                        jacobian: t.jacobian,
                        half,
                        reach: half * spread,
                    })
                })
        })
        .collect();
    ghosts.sort_by(|a, b| a.at[0].total_cmp(&b.at[0]));
    ghosts
}

impl ShellModel {
    /// Discretises the chart `surface`, whose domain lies in the box
    /// `lo..hi`, with `params`, for a shell of `material`; checks `cancel`
    /// as it goes.
    ///
    /// # Errors
    /// [`ShellError`]: a material or parameter out of range, the
    /// quadtree's refusals, a point whose supports cannot carry the basis
    /// (raise `eta`), a reference surface the projection cannot fit or
    /// that folds, cancellation.
    pub fn new(
        surface: &impl ShellSurface,
        lo: Point2,
        hi: Point2,
        material: Material,
        params: &ShellParams,
        cancel: &Cancel,
    ) -> Result<Self, ShellError> {
        material.validate()?;
        if params.order == Order::Constant {
            return Err(ShellError::ConstantBasis);
        }
        let tree = Quadtree::build(surface, lo, hi, &params.quadtree, cancel)?;
        let nodes: Vec<Vector> = tree
            .nodes()
            .iter()
            .map(|u| Vector::new(u[0], u[1], 0.0))
            .collect();
        let half = (0..nodes.len()).map(|k| tree.half_width(k)).collect();
        let ghosts = ghosts_of(surface, &tree);
        let ghost_reach = ghosts.iter().map(|g| g.reach).fold(0.0, Real::max);
        let mut model = Self {
            ghosts,
            ghost_reach,
            of_tree: (0..nodes.len() as u32).collect(),
            tree,
            material,
            order: params.order,
            nodes,
            half,
            reference: Vec::new(),
            points: Vec::new(),
        };
        let gauss = model.tree.gauss_points().to_vec();
        let stencils: Vec<(Point2, Real, Stencil)> = gauss
            .par_iter()
            .map(|g| {
                cancel.check().map_err(|_| ShellError::Cancelled)?;
                Ok((g.at, g.weight, model.stencil(g.at)?))
            })
            .collect::<Result<_, ShellError>>()?;
        let stencils = model.drop_unused(stencils);
        model.reference = model.project(surface, &stencils)?;
        let (young, poisson) = (material.young, material.poisson);
        model.points = stencils
            .into_par_iter()
            .map(|(at, weight, stencil)| {
                let reference = Reference::new(&stencil.local(&model.reference), young, poisson)
                    .ok_or(ShellError::Degenerate { at })?;
                Ok(SurfacePoint {
                    at,
                    weight,
                    stencil,
                    reference,
                })
            })
            .collect::<Result<_, ShellError>>()?;
        Ok(model)
    }

    /// The shell's material.
    pub fn material(&self) -> &Material {
        &self.material
    }

    /// The quadtree the nodes come from.
    pub fn tree(&self) -> &Quadtree {
        &self.tree
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Reference nodal positions `X_I` (not points of the surface: the
    /// surface is `sum_I N_I X_I`).
    pub fn reference(&self) -> &[Vector] {
        &self.reference
    }

    /// The quadrature points.
    pub fn points(&self) -> &[SurfacePoint] {
        &self.points
    }

    /// The shape functions at `u`.
    ///
    /// # Errors
    /// [`ShellError::Outside`] outside every leaf, or
    /// [`ShellError::Undersupported`] where the nodes covering `u` cannot
    /// carry the basis.
    pub fn stencil(&self, u: Point2) -> Result<Stencil, ShellError> {
        let leaf = self.tree.leaf_of(u).ok_or(ShellError::Outside { at: u })?;
        let mut near: Vec<(u32, Option<&Ghost>)> = self
            .tree
            .covering(u)
            .map(|k| (self.of_tree[k as usize], None))
            .filter(|&(k, _)| k != u32::MAX)
            .collect();
        if !self.ghosts.is_empty() {
            let first = self
                .ghosts
                .partition_point(|g| g.at[0] < u[0] - self.ghost_reach);
            near.extend(
                self.ghosts[first..]
                    .iter()
                    .take_while(|g| g.at[0] <= u[0] + self.ghost_reach)
                    .filter(|g| g.covers(u))
                    .map(|g| (self.of_tree[g.tree_node as usize], Some(g)))
                    .filter(|&(k, _)| k != u32::MAX),
            );
            near.sort_by_key(|&(k, _)| k);
        }
        let positions: Vec<Vector> = near
            .iter()
            .map(|&(k, ghost)| {
                ghost.map_or(self.nodes[k as usize], |g| {
                    Vector::new(g.at[0], g.at[1], 0.0)
                })
            })
            .collect();
        let mls = Mls::new(2, MlsParams::new(self.order, self.tree.half_width(leaf)))
            .map_err(|_| ShellError::Outside { at: u })?;
        let mut shapes = ShapeHessians::new();
        let undersupported = ShellError::Undersupported {
            at: u,
            supports: near.len(),
        };
        let fit = mls
            .shape_hessians_weighted(
                &Vector::new(u[0], u[1], 0.0),
                &positions,
                |i, d| match near[i] {
                    (_, Some(ghost)) => ghost.weight(d),
                    (k, None) => tensor_weight_hessian(2, d, &[self.half[k as usize]; 3]),
                },
                &mut shapes,
            )
            .map_err(|_| undersupported.clone())?;
        if fit.order != self.order {
            return Err(undersupported);
        }
        let rows = (0..near.len())
            .map(|i| {
                let (g, h) = (shapes.gradients()[i], shapes.hessians()[i]);
                [
                    shapes.values()[i],
                    g[0],
                    g[1],
                    h[(0, 0)],
                    h[(1, 1)],
                    h[(0, 1)],
                ]
            })
            .collect();
        Ok(Stencil {
            nodes: near.into_iter().map(|(k, _)| k).collect(),
            rows,
        })
    }

    /// Drops the nodes no quadrature point's stencil holds (see
    /// `of_tree`), renumbering the others in `stencils`.
    fn drop_unused(
        &mut self,
        mut stencils: Vec<(Point2, Real, Stencil)>,
    ) -> Vec<(Point2, Real, Stencil)> {
        let mut used = vec![false; self.nodes.len()];
        for (_, _, s) in &stencils {
            for &k in &s.nodes {
                used[k as usize] = true;
            }
        }
        if used.iter().all(|&u| u) {
            return stencils;
        }
        let mut next = 0u32;
        for (map, &u) in self.of_tree.iter_mut().zip(&used) {
            *map = if u {
                next += 1;
                next - 1
            } else {
                u32::MAX
            };
        }
        retain_used(&mut self.nodes, &used);
        retain_used(&mut self.half, &used);
        for (_, _, s) in &mut stencils {
            for k in &mut s.nodes {
                *k = self.of_tree[*k as usize];
            }
        }
        stencils
    }

    /// The sparsity of a matrix coupling the nodes that share a stencil,
    /// in 3 x 3 blocks.
    /// Also returns each block column's rows (sorted, the diagonal first).
    pub(super) fn pattern<'a>(
        &self,
        stencils: impl Iterator<Item = &'a Stencil>,
    ) -> Result<(BlockPattern, Vec<Vec<u32>>), ShellError> {
        let mut columns: Vec<Vec<u32>> = (0..self.nodes.len() as u32).map(|n| vec![n]).collect();
        for s in stencils {
            for (a, &n) in s.nodes.iter().enumerate() {
                columns[n as usize].extend_from_slice(&s.nodes[a + 1..]);
            }
        }
        for c in &mut columns {
            c[1..].sort_unstable();
            c.dedup();
        }
        let pattern = BlockPattern::new(3, &columns).ok_or(ShellError::TooLarge {
            nodes: self.nodes.len(),
        })?;
        Ok((pattern, columns))
    }

    /// Nodal positions whose interpolant is the L2 projection of the
    /// surface (see the module's documentation).
    fn project(
        &self,
        surface: &impl ShellSurface,
        stencils: &[(Point2, Real, Stencil)],
    ) -> Result<Vec<Vector>, ShellError> {
        let (pattern, _) = self.pattern(stencils.iter().map(|(_, _, s)| s))?;
        let mut touching: Vec<Vec<(u32, u32)>> = vec![Vec::new(); self.nodes.len()];
        for (p, (_, _, s)) in stencils.iter().enumerate() {
            for (a, &n) in s.nodes.iter().enumerate() {
                touching[n as usize].push((p as u32, a as u32));
            }
        }
        let mut rhs = vec![0.0; 3 * self.nodes.len()];
        for (at, weight, s) in stencils {
            let x = surface.position(*at);
            for (&k, row) in s.nodes.iter().zip(&s.rows) {
                for c in 0..3 {
                    rhs[3 * k as usize + c] += weight * row[0] * x[c];
                }
            }
        }
        let mut solver = SparseCholesky::default();
        let solution = solver
            .solve(
                &pattern,
                |n, column| {
                    for &(p, a) in &touching[n] {
                        let (_, weight, s) = &stencils[p as usize];
                        let na = weight * s.rows[a as usize][0];
                        for (&m, row) in s.nodes.iter().zip(&s.rows).skip(a as usize) {
                            if let Some(slot) = column.slot(m) {
                                for c in 0..3 {
                                    column.add(slot, c, c, na * row[0]);
                                }
                            }
                        }
                    }
                },
                rhs,
            )
            .ok_or(ShellError::Projection)?;
        Ok(solution
            .chunks_exact(3)
            .map(|c| Vector::new(c[0], c[1], c[2]))
            .collect())
    }
}

/// Keeps the entries of `v` whose `used` is true, in order.
fn retain_used<T>(v: &mut Vec<T>, used: &[bool]) {
    let mut k = 0;
    v.retain(|_| {
        k += 1;
        used[k - 1]
    });
}
