//! Gradient weights precomputed once in material coordinates (Lagrangian
//! kernels, tutorial Section 4 and Section 7.1; Müller et al. 2004): the
//! neighbours and the reference positions never change, so each
//! particle's weights `g_ij` are computed once and a displacement gradient
//! is then one pass over the neighbours,
//!
//! ```text
//! grad u (x_i) = sum_j (u_j - u_i) g_ij^T
//! ```
//!
//! The difference form is Eq. 37 as written; for shape-function
//! gradients it equals `sum_j u_j grad phi_j^T` because `sum_j grad phi_j
//! = 0` (partition of unity), and it cancels the rounding of a rigid
//! translation exactly.

use super::{Fit, GradientWeights, Mls, MlsError, Order, ShapeFunctions};
use crate::math::{Real, Vector};
use crate::neighbors::NeighborList;
use nalgebra::Matrix3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Particles per parallel work item.
const CHUNK: usize = 256;

/// Which gradient estimate to precompute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GradientKind {
    /// The direct estimate of Eq. 37-38 (Müller et al. 2004): cheaper, and
    /// what the elastic solids use.
    Direct,
    /// `grad phi_j(x_i)`, the derivative of the MLS approximation
    /// (Eq. 30-32). Where the fit falls back to the constant order these
    /// are Shepard's gradients: they annihilate constants only, and are
    /// not first-order accurate (the direct form gives zero there).
    ShapeFunctions,
}

/// Per particle: its neighbours, their gradient weights `g_ij`, the order
/// used and the moment matrix's condition number, stored flat (CSR).
#[derive(Debug, Clone, Default)]
pub struct LagrangianGradients {
    offsets: Vec<u32>,
    neighbours: Vec<u32>,
    weights: Vec<Vector>,
    orders: Vec<Order>,
    conditions: Vec<Real>,
}

impl LagrangianGradients {
    /// Precomputes the weights of every particle at its reference
    /// position in `positions`, over its neighbours in `list` (built from
    /// the same positions, with a radius of at least `h`). Runs in
    /// parallel; the result does not depend on the thread count.
    ///
    /// # Errors
    /// [`MlsError::LengthMismatch`] when `list` was built for another
    /// number of particles; [`MlsError::AtParticle`] when a shape-function
    /// fit finds no neighbour within `h` (never for a list that includes
    /// each particle itself, as [`NeighborList::build`] does).
    pub fn build(
        mls: &Mls,
        kind: GradientKind,
        positions: &[Vector],
        list: &NeighborList,
    ) -> Result<Self, MlsError> {
        let n = positions.len();
        if list.len() != n {
            return Err(MlsError::LengthMismatch {
                what: format!(
                    "the neighbour list has {} particles, the positions {n}; build the list from these positions",
                    list.len()
                ),
            });
        }
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0u32);
        let mut neighbours = Vec::with_capacity(list.pair_count());
        for i in 0..n {
            neighbours.extend_from_slice(list.of(i));
            offsets.push(neighbours.len() as u32);
        }
        let mut weights = vec![Vector::zeros(); neighbours.len()];
        let mut orders = vec![mls.params().order; n];
        let mut conditions = vec![0.0; n];

        // Split the flat weights into one contiguous slice per chunk.
        let mut items = Vec::with_capacity(n.div_ceil(CHUNK));
        let mut rest = weights.as_mut_slice();
        for ((c, orders), conditions) in orders
            .chunks_mut(CHUNK)
            .enumerate()
            .zip(conditions.chunks_mut(CHUNK))
        {
            let first = c * CHUNK;
            let len = (offsets[first + orders.len()] - offsets[first]) as usize;
            let (chunk, tail) = rest.split_at_mut(len);
            rest = tail;
            items.push((first, chunk, orders, conditions));
        }
        items
            .into_par_iter()
            .try_for_each(|(first, chunk, orders, conditions)| {
                let mut nodes = Vec::new();
                let mut shape = ShapeFunctions::new();
                let mut direct = GradientWeights::new();
                let base = offsets[first] as usize;
                for (k, (order, condition)) in
                    orders.iter_mut().zip(conditions.iter_mut()).enumerate()
                {
                    let i = first + k;
                    let (lo, hi) = (offsets[i] as usize, offsets[i + 1] as usize);
                    nodes.clear();
                    nodes.extend(neighbours[lo..hi].iter().map(|&j| positions[j as usize]));
                    let out = &mut chunk[lo - base..hi - base];
                    let fit: Fit = match kind {
                        GradientKind::Direct => {
                            let fit = mls.gradient_weights(&positions[i], &nodes, &mut direct);
                            out.copy_from_slice(direct.weights());
                            fit
                        }
                        GradientKind::ShapeFunctions => {
                            let fit = mls
                                .shape_functions(&positions[i], &nodes, &mut shape)
                                .map_err(|e| MlsError::AtParticle {
                                    particle: i,
                                    source: Box::new(e),
                                })?;
                            out.copy_from_slice(shape.gradients());
                            fit
                        }
                    };
                    *order = fit.order;
                    *condition = fit.condition;
                }
                Ok(())
            })?;
        Ok(Self {
            offsets,
            neighbours,
            weights,
            orders,
            conditions,
        })
    }

    /// Recomputes particle `i`'s direct gradient weights (Eq. 37-38) at
    /// its reference position in `positions`, over its neighbours as
    /// built, with the weight of its `k`-th neighbour given by
    /// `weight(k, &(x_i - x_j))` (`None` where the pair no longer
    /// interacts). Only `i`'s entries change: the fracturing solids
    /// refit just the particles a crack touched (tutorial Section 7.3).
    ///
    /// # Panics
    /// When `i` is not a particle of these gradients (a programming
    /// error: callers index their own particles).
    pub fn refit_direct(
        &mut self,
        mls: &Mls,
        i: usize,
        positions: &[Vector],
        weight: impl Fn(usize, &[Real; 3]) -> Option<Real>,
        scratch: &mut GradientWeights,
        nodes: &mut Vec<Vector>,
    ) {
        let range = self.range(i);
        nodes.clear();
        nodes.extend(
            self.neighbours[range.clone()]
                .iter()
                .map(|&j| positions[j as usize]),
        );
        let fit = mls.gradient_weights_weighted(&positions[i], nodes, weight, scratch);
        self.weights[range].copy_from_slice(scratch.weights());
        self.orders[i] = fit.order;
        self.conditions[i] = fit.condition;
    }

    /// Drops particle `i`'s gradient to the constant order: zero weights,
    /// so its displacement gradient is zero whatever its neighbours do.
    /// For a particle whose remaining neighbours resolve no gradient
    /// reliably (a fragment of a few particles in a line).
    pub fn clear(&mut self, i: usize) {
        let range = self.range(i);
        self.weights[range].fill(Vector::zeros());
        self.orders[i] = Order::Constant;
        self.conditions[i] = 1.0;
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.orders.len()
    }

    /// Whether no particle was precomputed.
    pub fn is_empty(&self) -> bool {
        self.orders.is_empty()
    }

    /// Order used at each particle.
    pub fn orders(&self) -> &[Order] {
        &self.orders
    }

    /// Condition number of each particle's moment matrix.
    pub fn conditions(&self) -> &[Real] {
        &self.conditions
    }

    /// Positions of particle `i`'s entries in the flat arrays
    /// [`Self::neighbour_indices`] and [`Self::all_weights`].
    pub fn range(&self, i: usize) -> std::ops::Range<usize> {
        self.offsets[i] as usize..self.offsets[i + 1] as usize
    }

    /// Every particle's neighbours, concatenated in particle order.
    pub fn neighbour_indices(&self) -> &[u32] {
        &self.neighbours
    }

    /// Every `g_ij`, aligned with [`Self::neighbour_indices`].
    pub fn all_weights(&self) -> &[Vector] {
        &self.weights
    }

    /// Neighbours of particle `i` and their weights `g_ij`.
    pub fn of(&self, i: usize) -> (&[u32], &[Vector]) {
        let (lo, hi) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        (&self.neighbours[lo..hi], &self.weights[lo..hi])
    }

    /// `grad f (x_i) = sum_j (f_j - f_i) g_ij` of a scalar field.
    pub fn scalar_gradient(&self, i: usize, f: &[Real]) -> Vector {
        let (js, gs) = self.of(i);
        js.iter()
            .zip(gs)
            .map(|(&j, g)| g * (f[j as usize] - f[i]))
            .sum()
    }

    /// `grad u (x_i) = sum_j (u_j - u_i) g_ij^T`, entry `(a, b) = du_a /
    /// dx_b`, of a vector field such as the displacement.
    pub fn vector_gradient(&self, i: usize, u: &[Vector]) -> Matrix3<Real> {
        let (js, gs) = self.of(i);
        js.iter()
            .zip(gs)
            .map(|(&j, g)| (u[j as usize] - u[i]) * g.transpose())
            .sum()
    }

    /// [`Self::vector_gradient`] of every particle into `out`, in
    /// parallel.
    ///
    /// # Panics
    /// When `u` or `out` does not have one entry per particle (a
    /// programming error: both are the solver's own arrays).
    pub fn vector_gradients(&self, u: &[Vector], out: &mut [Matrix3<Real>]) {
        assert_eq!(u.len(), self.len(), "one displacement per particle");
        assert_eq!(out.len(), self.len(), "one gradient per particle");
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, chunk)| {
                for (k, g) in chunk.iter_mut().enumerate() {
                    *g = self.vector_gradient(c * CHUNK + k, u);
                }
            });
    }
}
