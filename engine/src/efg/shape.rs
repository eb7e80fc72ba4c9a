//! MLS shape functions of the octree's nodes at many points, stored
//! sparse: the rows the Galerkin assembly, the embedded surface and the
//! constraints read (Guo–Qin, Section 3.1, with the tensor-product weight
//! of Eq. 12-13 on each node's cubic support).
//!
//! At a point `x` the covering nodes come from the octree's candidate
//! list of the leaf holding `x` (O(1), Section 4.1.2); the MLS fit is the
//! engine's own ([`Mls::shape_functions_weighted`]), with the basis
//! centred at `x` and scaled by the support half-width of that leaf.
//! A point where the fit is rank-deficient — fewer supports than the basis
//! has terms, or supports in a degenerate layout — is refused with its
//! position: the paper's patch covering condition (Eq. 8) made a checked
//! precondition rather than a silent drop of order.

use super::EfgError;
use crate::approx::mls::{Mls, MlsParams, Order, ShapeFunctions};
use crate::approx::tensor::tensor_weight;
use crate::cancel::Cancel;
use crate::geometry::octree::Octree;
use crate::math::{Brief, Real, Vector};
use rayon::prelude::*;

/// Why shape functions could not be had at a point.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CoverError {
    /// The point lies outside the octree's root cube.
    #[error("point ({}, {}, {}) lies outside the octree; it is not in the solid", Brief(.at[0]), Brief(.at[1]), Brief(.at[2]))]
    OutsideTree {
        /// The point.
        at: [Real; 3],
    },
    /// Too few supports, or a degenerate layout of them, cover the point.
    #[error(
        "point ({}, {}, {}) is covered by {supports} node supports in a layout that cannot fit \
         a {order:?} basis (it needs {needed} in general position); raise alpha, refine the \
         octree (a larger depth) or use the linear basis",
        Brief(.at[0]), Brief(.at[1]), Brief(.at[2])
    )]
    Uncovered {
        /// The point.
        at: [Real; 3],
        /// Supports with a positive weight there.
        supports: usize,
        /// The requested basis.
        order: Order,
        /// Terms of that basis.
        needed: usize,
    },
}

/// Points per parallel task of the interpolation: some 16 nodes each,
/// so a task is tens of microseconds, and a 6,000-point skin still splits
/// into six.
const POINTS_PER_TASK: usize = 1024;

/// Shape functions and gradients at a list of points, one sparse row
/// per point.
#[derive(Debug, Clone, Default)]
pub struct ShapeTable {
    offsets: Vec<u32>,
    nodes: Vec<u32>,
    values: Vec<Real>,
    gradients: Vec<Vector>,
}

/// One point's row.
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    /// Nodes with a non-zero shape function, ascending.
    pub nodes: &'a [u32],
    /// `phi_I(x)`.
    pub values: &'a [Real],
    /// `grad phi_I(x)`.
    pub gradients: &'a [Vector],
}

impl ShapeTable {
    /// Shape functions of `octree`'s nodes with a basis of `order` at
    /// every point of `points`, in parallel.
    ///
    /// # Errors
    /// [`CoverError`] for the first point (in order) outside the tree or
    /// not covered well enough.
    pub fn build(octree: &Octree, order: Order, points: &[Vector]) -> Result<Self, CoverError> {
        Self::build_with(octree, order, points, || Ok(()))
    }

    /// [`Self::build`] reading `cancel` before each point: the table of a
    /// solid's quadrature is its longest loop (millions of MLS fits).
    ///
    /// # Errors
    /// As [`Self::build`], and [`EfgError::Cancelled`] once `cancel` is
    /// raised.
    pub(super) fn build_cancellable(
        octree: &Octree,
        order: Order,
        points: &[Vector],
        cancel: &Cancel,
    ) -> Result<Self, EfgError> {
        Self::build_with(octree, order, points, || {
            cancel.check().map_err(|_| EfgError::Cancelled)
        })
    }

    /// The table, `stop` asked before each point whether to go on.
    fn build_with<E: From<CoverError> + Send>(
        octree: &Octree,
        order: Order,
        points: &[Vector],
        stop: impl Fn() -> Result<(), E> + Sync,
    ) -> Result<Self, E> {
        let rows: Vec<Result<RowData, E>> = points
            .par_iter()
            .map_init(
                || (ShapeFunctions::new(), Vec::new()),
                |(shape, positions), x| {
                    stop()?;
                    Ok(row(octree, order, x, shape, positions)?)
                },
            )
            .collect();
        let mut table = Self {
            offsets: Vec::with_capacity(points.len() + 1),
            ..Self::default()
        };
        table.offsets.push(0);
        for row in rows {
            let (nodes, values, gradients) = row?;
            table.nodes.extend(nodes);
            table.values.extend(values);
            table.gradients.extend(gradients);
            table.offsets.push(table.nodes.len() as u32);
        }
        Ok(table)
    }

    /// The number of points.
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Whether there is no point.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Point `i`'s row.
    pub fn row(&self, i: usize) -> Row<'_> {
        let r = self.offsets[i] as usize..self.offsets[i + 1] as usize;
        Row {
            nodes: &self.nodes[r.clone()],
            values: &self.values[r.clone()],
            gradients: &self.gradients[r],
        }
    }

    /// Non-zero entries over all rows.
    pub fn entries(&self) -> usize {
        self.nodes.len()
    }

    /// `sum_I phi_I(x_i) u_I` for every point, `u` one vector per node.
    pub fn interpolate(&self, u: &[Vector], out: &mut Vec<Vector>) {
        weighted_sums(&self.offsets, &self.nodes, &self.values, u, out, |_| {
            Vector::zeros()
        });
    }

    /// For each node, the points whose rows hold it (the transpose's
    /// pattern), as CSR offsets and point indices.
    pub fn points_by_node(&self, nodes: usize) -> (Vec<u32>, Vec<u32>) {
        let mut counts = vec![0u32; nodes + 1];
        for &n in &self.nodes {
            counts[n as usize + 1] += 1;
        }
        for i in 0..nodes {
            counts[i + 1] += counts[i];
        }
        let mut next = counts.clone();
        let mut points = vec![0u32; self.nodes.len()];
        for i in 0..self.len() {
            for &n in self.row(i).nodes {
                points[next[n as usize] as usize] = i as u32;
                next[n as usize] += 1;
            }
        }
        (counts, points)
    }
}

/// `base(i) + sum_I phi_I(x_i) u_I` into `out` for sparse rows given as
/// CSR `offsets`, `nodes` and `values` (f64, or f32 where a frame keeps
/// no more), in parallel over fixed runs of points. The hot loop of a
/// deforming skin: it streams each row's indices and values once, gathers
/// from `u` (a few kilobytes per thousand nodes, so cached) and keeps the
/// sums in registers, in f64.
pub(super) fn weighted_sums<V: Copy + Into<Real> + Sync>(
    offsets: &[u32],
    nodes: &[u32],
    values: &[V],
    u: &[Vector],
    out: &mut Vec<Vector>,
    base: impl Fn(usize) -> Vector + Sync,
) {
    out.resize(offsets.len() - 1, Vector::zeros());
    out.par_chunks_mut(POINTS_PER_TASK)
        .enumerate()
        .for_each(|(task, out)| {
            let first = task * POINTS_PER_TASK;
            for (k, o) in out.iter_mut().enumerate() {
                let i = first + k;
                let r = offsets[i] as usize..offsets[i + 1] as usize;
                let (nodes, values) = (&nodes[r.clone()], &values[r]);
                // Two sums per axis, over alternate entries: one chain of
                // additions would wait on the adder's latency each entry.
                let mut sums = [Vector::zeros(); 2];
                let pairs = nodes.chunks_exact(2).zip(values.chunks_exact(2));
                for (n, phi) in pairs {
                    for k in 0..2 {
                        sums[k] += u[n[k] as usize] * phi[k].into();
                    }
                }
                if nodes.len() % 2 == 1 {
                    let last = nodes.len() - 1;
                    sums[0] += u[nodes[last] as usize] * values[last].into();
                }
                *o = base(i) + (sums[0] + sums[1]);
            }
        });
}

/// One point's row as built: nodes, values, gradients.
type RowData = (Vec<u32>, Vec<Real>, Vec<Vector>);

/// One point's shape functions, its zero entries dropped.
fn row(
    octree: &Octree,
    order: Order,
    x: &Vector,
    shape: &mut ShapeFunctions,
    positions: &mut Vec<Vector>,
) -> Result<RowData, CoverError> {
    let at = [x[0], x[1], x[2]];
    let leaf = octree.leaf_at(x).ok_or(CoverError::OutsideTree { at })?;
    let candidates = octree.candidates(leaf);
    let nodes = octree.nodes();
    positions.clear();
    positions.extend(candidates.iter().map(|&n| nodes[n as usize].position));
    let scale = 0.5 * octree.alpha() * octree.leaves()[leaf as usize].size;
    let needed = order.basis_size(3);
    let uncovered = |supports| CoverError::Uncovered {
        at,
        supports,
        order,
        needed,
    };
    // The scale is positive and finite by construction.
    let mls = Mls::new(3, MlsParams::new(order, scale)).map_err(|_| uncovered(0))?;
    let weight = |i: usize, d: &[Real; 3]| {
        let h = nodes[candidates[i] as usize].half_width;
        tensor_weight(d, &[h; 3])
    };
    let fit = mls
        .shape_functions_weighted(x, positions, weight, shape)
        .map_err(|_| uncovered(0))?;
    if fit.order != order {
        return Err(uncovered(fit.support));
    }
    let mut out = (
        Vec::with_capacity(fit.support),
        Vec::with_capacity(fit.support),
        Vec::with_capacity(fit.support),
    );
    // Candidates are listed node by node in ascending order.
    for (i, &n) in candidates.iter().enumerate() {
        let phi = shape.values()[i];
        if phi != 0.0 || shape.gradients()[i] != Vector::zeros() {
            out.0.push(n);
            out.1.push(phi);
            out.2.push(shape.gradients()[i]);
        }
    }
    Ok(out)
}
