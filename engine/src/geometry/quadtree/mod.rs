//! The quadtree discretisation of a chart's parametric domain (Guo–Qin,
//! Section 4.2): the nodes of a thin shell live on the 2D domain a
//! conformal map flattens a surface patch onto, and a quadtree places
//! them where the surface needs them.
//!
//! **Refinement.** A conformal map scales lengths by one factor `lambda`
//! at each point, the same in every direction: a cell of parametric side
//! `l` spans about `lambda l` on the surface. A cell is split while
//! `lambda l` exceeds the resolution anywhere on it (read at its centre
//! and its corners), so the cells are about equally large on the surface
//! however the map stretches the chart. Only cells that may meet the
//! domain are kept (the domain's signed distance at the centre under half
//! the diagonal), and the tree is balanced so that no leaf has an edge or
//! corner neighbour more than one level coarser (the paper's one-level
//! adjusted tree): a support then reaches over leaves of at most three
//! sizes, and every point stays under enough supports.
//!
//! **Nodes and supports.** One node per leaf, at its centre, with a
//! square support of side `eta` times the leaf's side (the tensor-product
//! weight of Eq. 12-13 on it). With `eta = 3` a point lies in the open
//! supports of at least the three nodes a linear basis needs; a smaller
//! `eta` can leave points with fewer, which the build refuses, naming the
//! point. A node may lie just outside the domain (a leaf the boundary
//! crosses): nodes carry unknowns, not surface positions, so that is
//! harmless, as the paper's exterior-boundary nodes.
//!
//! **Integration.** Each leaf is cut into `subdivision^2` integration
//! cells, each with the tensor-product Gauss–Legendre rule (one rule per
//! leaf misjudges a bending energy, see [`QuadtreeParams::subdivision`]);
//! points outside the domain are
//! dropped, so a cell the boundary cuts integrates over its part inside
//! to the resolution of its points. The weights are parametric areas: the
//! mechanics multiply them by the surface's area element `lambda^2`.
//!
//! **Lookup.** Leaves are keyed by level and integer coordinates; the
//! leaf holding a point is found by walking up from the deepest level,
//! and each leaf lists the nodes whose supports overlap it, so the
//! supports covering a point are read from one short list.

use crate::approx::gauss::{MAX_ORDER, gauss_legendre};
use crate::cancel::Cancel;
use crate::math::{Brief, Real};
use std::collections::HashSet;

#[cfg(test)]
mod tests;

/// A point of the parametric domain.
pub type Point2 = [Real; 2];

/// Deepest quadtree accepted: 2^20 cells along an axis.
pub const MAX_DEPTH: u32 = 20;

/// Most leaves a build may create, counted as it goes, so that a too
/// fine resolution fails before it exhausts memory.
pub const MAX_LEAVES: usize = 1_000_000;

/// Leaves handled between two reads of the cancel flag.
const CHECK_EVERY: usize = 1024;

/// Supports a point needs: a linear basis in 2D has three terms.
pub const MIN_SUPPORTS: usize = 3;

/// A chart's parametric domain as the quadtree reads it.
pub trait ChartDomain {
    /// Signed distance to the domain's boundary, negative inside; it may
    /// be a bound (at most the true distance in magnitude), as only its
    /// sign and a comparison with a cell's half diagonal are read.
    fn distance(&self, u: Point2) -> Real;

    /// The conformal factor `lambda(u) > 0`: a short length `l` at `u` is
    /// `lambda l` on the surface. Read at cells' corners too, which may
    /// lie just outside the domain: continue it there.
    fn lambda(&self, u: Point2) -> Real;

    /// Whether `u` lies in the domain (`distance(u) <= 0`): read for
    /// every quadrature point, so a domain with a cheaper test than its
    /// distance (a chart: the triangle under the point) gives it.
    fn contains(&self, u: Point2) -> bool {
        self.distance(u) <= 0.0
    }
}

/// How a quadtree is cut.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadtreeParams {
    /// Largest size of a cell on the surface, `lambda l` (the resolution
    /// knob), in the surface's length unit.
    pub resolution: Real,
    /// Support side in leaf sides, `eta` (3: every point under at least
    /// three supports).
    pub eta: Real,
    /// Gauss points per axis of a cell, 1 to [`MAX_ORDER`].
    pub gauss_order: usize,
    /// Integration cells per leaf side, 1 to 8: each leaf is cut into
    /// `subdivision^2` cells, each with the Gauss rule. The shape
    /// functions' second derivatives jump where the weight's spline
    /// changes branch, inside leaves, so one rule per leaf integrates a
    /// bending energy poorly (the clamped plate in `engine/tests/plate.rs`,
    /// at 16 cells a side, deflects 1.40 times Timoshenko's with 1 and
    /// 0.94 times with 2).
    pub subdivision: usize,
    /// Deepest level (the root is level 0), at most [`MAX_DEPTH`].
    pub max_depth: u32,
    /// Rings of leaves kept outside the domain, 0 to 2: a leaf is kept
    /// while its centre lies within `exterior` of its own sides (plus half
    /// its diagonal) of the domain. Their nodes carry no quadrature but
    /// give a point near the boundary supports on its outer side too:
    /// the paper's exterior nodes, which a quadratic basis needs at the
    /// domain's corners (with one ring, `eta = 4` puts three nodes along
    /// each axis over every point). With rings the root box is the
    /// domain's box doubled about its centre, so that they fit.
    pub exterior: u32,
}

impl QuadtreeParams {
    /// Cells of `resolution` on the surface, `eta = 3`, 4 x 4 Gauss points
    /// on each of 2 x 2 integration cells per leaf, at most 12 levels.
    pub fn new(resolution: Real) -> Self {
        Self {
            resolution,
            eta: 3.0,
            gauss_order: 4,
            subdivision: 2,
            max_depth: 12,
            exterior: 0,
        }
    }
}

/// Why a quadtree could not be built. Each message says what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum QuadtreeError {
    /// A parameter is out of range.
    #[error("quadtree `{what}` is {got}; use {range}")]
    Parameter {
        /// The parameter.
        what: &'static str,
        /// Its accepted range.
        range: &'static str,
        /// Its value, briefly.
        got: Brief,
    },
    /// The domain's box is empty or not finite.
    #[error("the chart's parametric box is empty or not finite; check the chart")]
    BadBounds,
    /// The resolution asks for more leaves than [`MAX_LEAVES`].
    #[error(
        "cells of {resolution} on the surface need more than {max} quadtree leaves; \
         use a coarser resolution"
    )]
    TooFine {
        /// The requested resolution.
        resolution: Brief,
        /// The bound.
        max: usize,
    },
    /// No cell meets the domain.
    #[error("no quadtree cell meets the chart's domain; check the chart (it may be empty)")]
    Empty,
    /// A point of the domain lies in fewer supports than a linear basis
    /// needs.
    #[error(
        "point ({}, {}) of the chart lies in {supports} node supports, fewer than the \
         {MIN_SUPPORTS} a linear basis needs; raise eta (3 always suffices)",
        Brief(.at[0]), Brief(.at[1])
    )]
    Uncovered {
        /// The point.
        at: Point2,
        /// Supports covering it.
        supports: usize,
    },
    /// The build was cancelled.
    #[error("the quadtree build was cancelled")]
    Cancelled,
}

/// A cell: its level and integer coordinates at that level.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Cell {
    /// Level, 0 at the root.
    pub level: u32,
    /// Column, `0..2^level`.
    pub i: u32,
    /// Row, `0..2^level`.
    pub j: u32,
}

impl Cell {
    fn children(self) -> [Cell; 4] {
        let (level, i, j) = (self.level + 1, 2 * self.i, 2 * self.j);
        [
            Cell { level, i, j },
            Cell { level, i: i + 1, j },
            Cell { level, i, j: j + 1 },
            Cell {
                level,
                i: i + 1,
                j: j + 1,
            },
        ]
    }
}

/// A quadrature point: where, the parametric area it stands for, and the
/// leaf holding it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussPoint {
    /// Position in the parametric domain.
    pub at: Point2,
    /// Parametric area.
    pub weight: Real,
    /// Index of its leaf (and of that leaf's node).
    pub leaf: u32,
}

/// A balanced quadtree over a chart's domain, its nodes, their supports
/// and its quadrature (see the module's documentation).
#[derive(Debug, Clone)]
pub struct Quadtree {
    origin: Point2,
    side: Real,
    /// Rings of exterior leaves ([`QuadtreeParams::exterior`]).
    exterior: Real,
    eta: Real,
    /// Leaves in (level, i, j) order; node `k` is leaf `k`'s centre.
    leaves: Vec<Cell>,
    set: HashSet<Cell>,
    depth: u32,
    /// Per leaf, the nodes whose supports overlap it, ascending.
    covers: Vec<Vec<u32>>,
    gauss: Vec<GaussPoint>,
}

impl Quadtree {
    /// Builds the tree over `domain`, whose points lie in the box `lo..hi`;
    /// checks `cancel` as it goes.
    ///
    /// # Errors
    /// [`QuadtreeError`]: a parameter out of range, a bad box, a too fine
    /// resolution, an empty domain, a Gauss point under fewer than three
    /// supports, or cancellation.
    pub fn build(
        domain: &impl ChartDomain,
        lo: Point2,
        hi: Point2,
        params: &QuadtreeParams,
        cancel: &Cancel,
    ) -> Result<Self, QuadtreeError> {
        check(params)?;
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        if !(lo.iter().chain(&hi).all(|v| v.is_finite()) && extent > 0.0 && extent.is_finite()) {
            return Err(QuadtreeError::BadBounds);
        }
        let (origin, side) = if params.exterior == 0 {
            (lo, extent)
        } else {
            let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
            ([centre[0] - extent, centre[1] - extent], 2.0 * extent)
        };
        let mut tree = Self {
            origin,
            side,
            exterior: Real::from(params.exterior),
            eta: params.eta,
            leaves: Vec::new(),
            set: HashSet::new(),
            depth: 0,
            covers: Vec::new(),
            gauss: Vec::new(),
        };
        let too_fine = || QuadtreeError::TooFine {
            resolution: Brief(params.resolution),
            max: MAX_LEAVES,
        };
        let checked = |count: usize| -> Result<(), QuadtreeError> {
            if count.is_multiple_of(CHECK_EVERY) {
                cancel.check().map_err(|_| QuadtreeError::Cancelled)?;
            }
            Ok(())
        };

        // Refinement, from the root.
        let mut stack = vec![Cell {
            level: 0,
            i: 0,
            j: 0,
        }];
        let mut visited = 0usize;
        while let Some(cell) = stack.pop() {
            visited += 1;
            checked(visited)?;
            if !tree.meets(domain, cell) {
                continue;
            }
            if cell.level < params.max_depth && tree.surface_size(domain, cell) > params.resolution
            {
                stack.extend(cell.children());
            } else {
                tree.set.insert(cell);
                if tree.set.len() > MAX_LEAVES {
                    return Err(too_fine());
                }
            }
        }
        if tree.set.is_empty() {
            return Err(QuadtreeError::Empty);
        }

        // Balance: a leaf whose edge or corner neighbour is two or more
        // levels coarser splits that neighbour, until none does.
        let mut queue: Vec<Cell> = tree.set.iter().copied().collect();
        queue.sort_unstable();
        while let Some(cell) = queue.pop() {
            visited += 1;
            checked(visited)?;
            if !tree.set.contains(&cell) {
                continue;
            }
            let span = 1i64 << cell.level;
            for (di, dj) in NEIGHBOURS {
                let (ni, nj) = (i64::from(cell.i) + di, i64::from(cell.j) + dj);
                if !(0..span).contains(&ni) || !(0..span).contains(&nj) {
                    continue;
                }
                let Some(coarse) = tree.containing(cell.level, ni as u32, nj as u32) else {
                    continue;
                };
                if coarse.level + 1 < cell.level {
                    tree.set.remove(&coarse);
                    for child in coarse.children() {
                        if tree.meets(domain, child) {
                            tree.set.insert(child);
                            queue.push(child);
                        }
                    }
                    if tree.set.len() > MAX_LEAVES {
                        return Err(too_fine());
                    }
                    // This leaf may still see a too coarse neighbour.
                    queue.push(cell);
                }
            }
        }
        tree.leaves = tree.set.iter().copied().collect();
        tree.leaves.sort_unstable();
        tree.depth = tree.leaves.iter().map(|c| c.level).max().unwrap_or(0);
        tree.list_covers(cancel)?;
        tree.integrate(domain, params.gauss_order, params.subdivision)?;
        Ok(tree)
    }

    /// The leaves, in (level, i, j) order.
    pub fn leaves(&self) -> &[Cell] {
        &self.leaves
    }

    /// Node `k`: the centre of leaf `k`.
    pub fn node(&self, k: usize) -> Point2 {
        self.centre(self.leaves[k])
    }

    /// Every node, in leaf order.
    pub fn nodes(&self) -> Vec<Point2> {
        self.leaves.iter().map(|c| self.centre(*c)).collect()
    }

    /// Half the side of node `k`'s square support.
    pub fn half_width(&self, k: usize) -> Real {
        0.5 * self.eta * self.cell_side(self.leaves[k].level)
    }

    /// A cell's lower corner and side.
    pub fn bounds(&self, cell: Cell) -> (Point2, Real) {
        let side = self.cell_side(cell.level);
        (
            [
                self.origin[0] + Real::from(cell.i) * side,
                self.origin[1] + Real::from(cell.j) * side,
            ],
            side,
        )
    }

    /// The quadrature points inside the domain.
    pub fn gauss_points(&self) -> &[GaussPoint] {
        &self.gauss
    }

    /// Index of the leaf holding `u`, or `None` outside every leaf.
    pub fn leaf_of(&self, u: Point2) -> Option<usize> {
        let cells = Real::from(1u32 << self.depth);
        let at = |k: usize| {
            let t = (u[k] - self.origin[k]) / self.side * cells;
            (t.is_finite() && t >= 0.0 && t <= cells).then(|| (t as u32).min((1 << self.depth) - 1))
        };
        let (i, j) = (at(0)?, at(1)?);
        let cell = self.containing(self.depth, i, j)?;
        self.leaves.binary_search(&cell).ok()
    }

    /// The nodes whose open supports hold `u`, ascending; empty outside
    /// every leaf.
    pub fn covering(&self, u: Point2) -> impl Iterator<Item = u32> + '_ {
        let list = self
            .leaf_of(u)
            .map_or(&[][..], |leaf| &self.covers[leaf][..]);
        list.iter().copied().filter(move |&k| {
            let (x, h) = (self.node(k as usize), self.half_width(k as usize));
            (u[0] - x[0]).abs() < h && (u[1] - x[1]).abs() < h
        })
    }

    fn cell_side(&self, level: u32) -> Real {
        self.side / Real::from(1u32 << level)
    }

    fn centre(&self, cell: Cell) -> Point2 {
        let (lo, side) = self.bounds(cell);
        [lo[0] + 0.5 * side, lo[1] + 0.5 * side]
    }

    /// Whether `cell` may meet the domain.
    fn meets(&self, domain: &impl ChartDomain, cell: Cell) -> bool {
        let side = self.cell_side(cell.level);
        let d = domain.distance(self.centre(cell));
        d < (std::f64::consts::FRAC_1_SQRT_2 + self.exterior) * side
    }

    /// The largest `lambda l` over the cell's centre and corners.
    fn surface_size(&self, domain: &impl ChartDomain, cell: Cell) -> Real {
        let (lo, side) = self.bounds(cell);
        let c = self.centre(cell);
        [
            c,
            lo,
            [lo[0] + side, lo[1]],
            [lo[0], lo[1] + side],
            [lo[0] + side, lo[1] + side],
        ]
        .iter()
        .map(|u| domain.lambda(*u))
        .fold(0.0, Real::max)
            * side
    }

    /// The leaf holding the level-`level` cell `(i, j)`, if one at that
    /// level or coarser does.
    fn containing(&self, level: u32, i: u32, j: u32) -> Option<Cell> {
        (0..=level).rev().find_map(|k| {
            let cell = Cell {
                level: k,
                i: i >> (level - k),
                j: j >> (level - k),
            };
            self.set.contains(&cell).then_some(cell)
        })
    }

    /// For each node, the leaves its support overlaps: the cells of its
    /// own level under its box, and where those are split, the leaves
    /// below them that overlap it.
    fn list_covers(&mut self, cancel: &Cancel) -> Result<(), QuadtreeError> {
        // The cells with leaves below them, so a descent never wanders
        // through empty space.
        let mut internal = HashSet::new();
        for leaf in &self.leaves {
            let mut cell = *leaf;
            while cell.level > 0 {
                cell = Cell {
                    level: cell.level - 1,
                    i: cell.i / 2,
                    j: cell.j / 2,
                };
                if !internal.insert(cell) {
                    break;
                }
            }
        }
        let mut covers = vec![Vec::new(); self.leaves.len()];
        for (k, &leaf) in self.leaves.iter().enumerate() {
            if k % CHECK_EVERY == 0 {
                cancel.check().map_err(|_| QuadtreeError::Cancelled)?;
            }
            let (x, h) = (self.node(k), self.half_width(k));
            let side = self.cell_side(leaf.level);
            let span = i64::from(1u32 << leaf.level);
            let range = |axis: usize| {
                let lo = ((x[axis] - h - self.origin[axis]) / side).floor() as i64;
                let hi = ((x[axis] + h - self.origin[axis]) / side).ceil() as i64 - 1;
                lo.max(0)..=hi.min(span - 1)
            };
            let overlaps = |cell: Cell| {
                let (lo, s) = self.bounds(cell);
                (0..2).all(|a| lo[a] < x[a] + h && lo[a] + s > x[a] - h)
            };
            for i in range(0) {
                for j in range(1) {
                    let cell = Cell {
                        level: leaf.level,
                        i: i as u32,
                        j: j as u32,
                    };
                    if let Some(coarse) = self.containing(leaf.level, cell.i, cell.j) {
                        if overlaps(coarse) {
                            covers[self.index(coarse)].push(k as u32);
                        }
                        continue;
                    }
                    // A finer region (or none): its leaves that overlap
                    // the box.
                    let mut stack = vec![cell];
                    while let Some(cell) = stack.pop() {
                        if !internal.contains(&cell) || !overlaps(cell) {
                            continue;
                        }
                        for child in cell.children() {
                            if self.set.contains(&child) {
                                if overlaps(child) {
                                    covers[self.index(child)].push(k as u32);
                                }
                            } else {
                                stack.push(child);
                            }
                        }
                    }
                }
            }
        }
        for list in &mut covers {
            list.sort_unstable();
            list.dedup();
        }
        self.covers = covers;
        Ok(())
    }

    fn index(&self, cell: Cell) -> usize {
        self.leaves
            .binary_search(&cell)
            .expect("a leaf of the tree is in its sorted list")
    }

    /// The Gauss points of every leaf inside the domain; refuses one under
    /// fewer than [`MIN_SUPPORTS`] supports.
    fn integrate(
        &mut self,
        domain: &impl ChartDomain,
        order: usize,
        subdivision: usize,
    ) -> Result<(), QuadtreeError> {
        let (x, w) = gauss_legendre(order);
        let per_leaf = (order * subdivision).pow(2);
        let mut gauss = Vec::with_capacity(self.leaves.len() * per_leaf);
        for (k, &leaf) in self.leaves.iter().enumerate() {
            let (lo, side) = self.bounds(leaf);
            let cell = side / subdivision as Real;
            let half = 0.5 * cell;
            for a in 0..subdivision {
                for b in 0..subdivision {
                    let corner = [lo[0] + a as Real * cell, lo[1] + b as Real * cell];
                    for (xa, wa) in x.iter().zip(w) {
                        for (xb, wb) in x.iter().zip(w) {
                            let at = [corner[0] + half * (1.0 + xa), corner[1] + half * (1.0 + xb)];
                            if !domain.contains(at) {
                                continue;
                            }
                            gauss.push(GaussPoint {
                                at,
                                weight: wa * wb * half * half,
                                leaf: k as u32,
                            });
                        }
                    }
                }
            }
        }
        for point in &gauss {
            let supports = self.covering(point.at).count();
            if supports < MIN_SUPPORTS {
                return Err(QuadtreeError::Uncovered {
                    at: point.at,
                    supports,
                });
            }
        }
        self.gauss = gauss;
        Ok(())
    }
}

/// The eight edge and corner neighbours' offsets.
const NEIGHBOURS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

fn check(params: &QuadtreeParams) -> Result<(), QuadtreeError> {
    if !(params.resolution.is_finite() && params.resolution > 0.0) {
        return Err(QuadtreeError::Parameter {
            what: "resolution",
            range: "a positive, finite length",
            got: Brief(params.resolution),
        });
    }
    if !(params.eta.is_finite() && params.eta > 1.0 && params.eta <= 8.0) {
        return Err(QuadtreeError::Parameter {
            what: "eta",
            range: "a support side in (1, 8] leaf sides (3 by default)",
            got: Brief(params.eta),
        });
    }
    if !(1..=MAX_ORDER).contains(&params.gauss_order) {
        return Err(QuadtreeError::Parameter {
            what: "gauss_order",
            range: "1 to 5 Gauss points per axis",
            got: Brief(params.gauss_order as Real),
        });
    }
    if !(1..=8).contains(&params.subdivision) {
        return Err(QuadtreeError::Parameter {
            what: "subdivision",
            range: "1 to 8 integration cells per leaf side",
            got: Brief(params.subdivision as Real),
        });
    }
    if params.exterior > 2 {
        return Err(QuadtreeError::Parameter {
            what: "exterior",
            range: "0 to 2 rings of leaves outside the domain",
            got: Brief(Real::from(params.exterior)),
        });
    }
    if params.max_depth > MAX_DEPTH {
        return Err(QuadtreeError::Parameter {
            what: "max_depth",
            range: "at most 20 levels",
            got: Brief(Real::from(params.max_depth)),
        });
    }
    Ok(())
}
