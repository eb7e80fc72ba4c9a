//! The direct first-derivative estimate of Müller et al. 2004 (tutorial
//! Eq. 35-38), generalised from the linear to any basis order.
//!
//! At a sample point `x` whose own value `f(x)` is known (a particle),
//! the local polynomial is pinned to that value and only its
//! non-constant coefficients are fitted, in the centred, scaled basis
//! without the constant, `p'(s) = [s, s_a s_b, ...]`, `s_j = (x_j - x)/h`:
//!
//! ```text
//! E = sum_j w_j (f_j - f(x) - p'_j^T a')^2
//! A = sum_j w_j p'_j p'_j^T                          (Eq. 38, scaled)
//! a' = A^-1 sum_j w_j p'_j (f_j - f(x))              (Eq. 37)
//! grad f(x) = (1/h) a'[0..d]                         (the linear terms)
//! ```
//!
//! For the linear order `p'(s) = s` and this is exactly Eq. 37-38 with
//! `x_ij / h` for `x_ij`. The gradient weights are then
//! `g_j = (w_j / h) (A^-1 p'_j)[0..d]` and `grad f(x) = sum_j g_j (f_j -
//! f(x))`. A node at `x` itself has `p' = 0` and weighs nothing. The rank
//! fallback ends at the constant order, whose gradient is zero (no
//! direction is resolved): that is not an error here, since `f(x)` itself
//! is known.

use super::{Fit, Mls, Order, Scratch};
use crate::math::{Real, Vector};

/// Gradient weights `g_j` of one direct estimate, one entry per node
/// passed to [`Mls::gradient_weights`] (zero outside the support), and the
/// scratch memory reused between estimates.
#[derive(Debug, Clone, Default)]
pub struct GradientWeights {
    weights: Vec<Vector>,
    scratch: Scratch,
}

impl GradientWeights {
    /// Empty weights and scratch, to pass to [`Mls::gradient_weights`]
    /// and reuse across estimates.
    pub fn new() -> Self {
        Self::default()
    }

    /// `g_j`: `grad f(x) = sum_j g_j (f_j - f(x))`; components past the
    /// dimension are zero.
    pub fn weights(&self) -> &[Vector] {
        &self.weights
    }

    /// `sum_j g_j (f_j - f_x)`.
    pub fn gradient(&self, f: &[Real], f_x: Real) -> Vector {
        self.weights
            .iter()
            .zip(f)
            .map(|(g, f)| g * (*f - f_x))
            .sum()
    }
}

impl Mls {
    /// The Eq. 37-38 gradient weights at the sample point `x` for the
    /// sample positions `nodes`, written to `out`. The order drops where
    /// `A` is rank-deficient (down to the constant order, zero weights);
    /// the returned [`Fit`] says which order was used. Never fails: with
    /// no node in the support the gradient is zero at the constant order.
    /// Sequential; allocates only while `out` grows.
    pub fn gradient_weights(&self, x: &Vector, nodes: &[Vector], out: &mut GradientWeights) -> Fit {
        self.gradient_weights_weighted(x, nodes, |_, d| self.weight(d).map(|(w, _)| w), out)
    }

    /// [`Mls::gradient_weights`] with each node's weight given by the
    /// caller: `weight(i, &(x - x_i))` returns node `i`'s weight, or
    /// `None` (or a weight at or below zero) where it does not take part.
    /// The fracturing solids use it for the transparency weights of
    /// tutorial Eq. 70, which lengthen the distance of a pair a crack
    /// passes between; the parameters' `h` stays the basis scale.
    pub fn gradient_weights_weighted(
        &self,
        x: &Vector,
        nodes: &[Vector],
        weight: impl Fn(usize, &[Real; 3]) -> Option<Real>,
        out: &mut GradientWeights,
    ) -> Fit {
        out.weights.clear();
        out.weights.resize(nodes.len(), Vector::zeros());
        let s = &mut out.scratch;
        // The direct estimate reads no weight gradient.
        s.gather(self, x, nodes, |i, d| {
            weight(i, d).filter(|w| *w > 0.0).map(|w| (w, [0.0; 3]))
        });
        let support = s.nodes.len();
        let mut order = self.params.order;
        loop {
            // The basis without its constant entry.
            let n = order.basis_size(self.dim) - 1;
            if n == 0 {
                return Fit {
                    order: Order::Constant,
                    condition: 1.0,
                    support,
                };
            }
            let inversion = s.invert_moment(1, n, self.params.rank_tolerance);
            if inversion.rank == n {
                let inv = &s.inverse;
                for node in &s.nodes {
                    let p = &node.basis.p[1..=n];
                    let g = &mut out.weights[node.index];
                    for k in 0..self.dim {
                        let row: Real = (0..n).map(|b| inv[k * n + b] * p[b]).sum();
                        g[k] = node.w * self.inv_h * row;
                    }
                }
                return Fit {
                    order,
                    condition: inversion.condition,
                    support,
                };
            }
            // Constant is the last: its empty basis ends the loop above.
            order = order.lower().unwrap_or(Order::Constant);
        }
    }
}
