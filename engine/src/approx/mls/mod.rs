//! Moving-least-squares (MLS) approximation (Adams–Wicke tutorial,
//! Section 3; Müller et al. 2004 for elastic solids).
//!
//! Around an evaluation point `x`, MLS fits the polynomial `p^T a` that
//! best matches the samples `f_i` in the weighted least-squares sense
//! (Eq. 21-25). With the basis centred at `x` and scaled by `h`,
//! `p_i = p((x_i - x) / h)` (Eq. 28), the moment matrix is
//!
//! ```text
//! M(x) = sum_i w_i(x) p_i p_i^T,     w_i(x) = W(|x - x_i| / h)
//! ```
//!
//! and the shape functions are `phi_i(x) = w_i p(0)^T M^-1 p_i` (Eq. 29,
//! the centred form of Eq. 27), so that `<f>(x) = sum_i phi_i f_i`
//! reproduces every polynomial up to the basis order (Section 3.2).
//!
//! - [`Mls::shape_functions`]: `phi_i` and `grad phi_i` (Eq. 30-31 in the
//!   centred form, derived in `shape.rs`);
//! - [`Mls::shape_hessians_weighted`]: `phi_i`, `grad phi_i` and their
//!   Hessians, for the bending energy of thin shells (`hessian.rs`);
//! - [`Mls::gradient_weights`]: the direct first-derivative estimate of
//!   Müller et al. (Eq. 35-38), generalised to any order, which the
//!   elastic solids use;
//! - [`LagrangianGradients`]: those weights precomputed once per particle
//!   in material coordinates (Lagrangian kernels, Section 4), so a
//!   displacement gradient costs one pass over the neighbours.
//!
//! **Safe inversion and rank fallback.** `M` is inverted through its
//! symmetric eigen-decomposition (the SVD the tutorial advises in Section
//! 3.3), and is declared rank-deficient when an eigenvalue is at or below
//! `rank_tolerance * lambda_max`. Then the order drops, quadratic ->
//! linear -> constant (MLSPH, Dilts 1999; tutorial Section 4), and the
//! order actually used is reported in [`Fit`]. Only when no node has a
//! positive weight does the fit fail, with [`MlsError::NoSupport`];
//! nothing here returns NaN.
//!
//! **Weight.** `W` is the profile of one of the engine's smooth kernels
//! ([`KernelKind`]), unnormalised: the shape functions do not change when
//! `w` is scaled (`M^-1` scales inversely). The default is poly6,
//! `(1 - q^2)^3`, the weight Müller et al. 2004 use. Kernels with a kink or
//! a pole at the origin (spiky, viscosity) are refused: `grad w_i` would be
//! undefined at a node.

mod basis;
mod direct;
mod hessian;
mod inverse;
mod lagrangian;
mod shape;

pub use basis::{MAX_BASIS, Order};
pub use direct::GradientWeights;
pub use hessian::ShapeHessians;
pub use lagrangian::{GradientKind, LagrangianGradients};
pub use shape::ShapeFunctions;

use super::KernelKind;
use crate::math::{Real, Vector};
use basis::BasisValues;
use inverse::{Inversion, Square, pseudo_inverse};
use serde::{Deserialize, Serialize};

/// Why an MLS fit or precomputation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MlsError {
    /// No node lies within the support, so not even the constant basis
    /// can be fitted.
    #[error(
        "MLS at {at:?}: none of the {nodes} nodes lies within the support radius h = {h}; \
         increase h or add nodes near this point"
    )]
    NoSupport {
        /// The evaluation point `x` (length unit of the nodes).
        at: [Real; 3],
        /// How many nodes were offered; none had a positive weight at `at`.
        nodes: usize,
        /// The support radius that missed them (length unit of the nodes).
        h: Real,
    },
    /// A parameter is out of range.
    #[error("MLS parameter `{field}`: {message}")]
    InvalidParameter {
        /// The parameter at fault: `dim`, `h`, `rank_tolerance` or `weight`.
        field: &'static str,
        /// Its value and what to use instead.
        message: String,
    },
    /// Inputs of different lengths.
    #[error("MLS precomputation: {what}")]
    LengthMismatch {
        /// Which inputs disagree, with both lengths.
        what: String,
    },
    /// A fit failed during a precomputation.
    #[error("MLS precomputation at particle {particle}: {source}")]
    AtParticle {
        /// Index of the particle whose fit failed.
        particle: usize,
        /// Why it failed.
        #[source]
        source: Box<MlsError>,
    },
}

/// Parameters of an MLS approximation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MlsParams {
    /// Requested basis order; lowered per point where `M` is
    /// rank-deficient.
    pub order: Order,
    /// Support radius `h` of the weight, also the basis scale (Eq. 28).
    pub h: Real,
    /// Weight profile `W(q)`, `q = r / h`.
    pub weight: KernelKind,
    /// Relative eigenvalue threshold: `M` is rank-deficient when an
    /// eigenvalue is at or below `rank_tolerance * lambda_max`, that is
    /// when its condition number exceeds `1 / rank_tolerance`.
    pub rank_tolerance: Real,
}

impl MlsParams {
    /// Default relative eigenvalue threshold.
    pub const DEFAULT_RANK_TOLERANCE: Real = 1e-10;

    /// Order `order`, support `h`, the poly6 weight of Müller et al. 2004
    /// and the default threshold.
    pub fn new(order: Order, h: Real) -> Self {
        Self {
            order,
            h,
            weight: KernelKind::Poly6,
            rank_tolerance: Self::DEFAULT_RANK_TOLERANCE,
        }
    }
}

/// What one fit used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// The order actually used: the requested one unless the moment
    /// matrix was rank-deficient there.
    pub order: Order,
    /// Condition number `lambda_max / lambda_min` of the moment matrix at
    /// that order (for the direct gradient, of the reduced matrix `A`;
    /// 1 when it has no entry, the constant order of the direct form).
    pub condition: Real,
    /// Nodes with a positive weight.
    pub support: usize,
}

/// A validated MLS approximation in 1, 2 or 3 dimensions; only the first
/// `dim` components of positions are read. Cheap to copy; the scratch
/// memory lives in the caller's [`ShapeFunctions`] or [`GradientWeights`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mls {
    dim: usize,
    params: MlsParams,
    inv_h: Real,
}

impl Mls {
    /// An MLS approximation in `dim` dimensions, its parameters checked.
    ///
    /// # Errors
    /// [`MlsError::InvalidParameter`] when `dim` is not 1, 2 or 3, `h` is
    /// not positive and finite, `rank_tolerance` is not in (0, 1), or the
    /// weight is not smooth at the origin (spiky, viscosity).
    pub fn new(dim: usize, params: MlsParams) -> Result<Self, MlsError> {
        let invalid = |field, message: String| Err(MlsError::InvalidParameter { field, message });
        if !(1..=3).contains(&dim) {
            return invalid(
                "dim",
                format!("is {dim}; MLS works in 1, 2 or 3 dimensions"),
            );
        }
        if !(params.h.is_finite() && params.h > 0.0) {
            return invalid(
                "h",
                format!(
                    "is {}; the support radius must be positive and finite",
                    params.h
                ),
            );
        }
        if !(params.rank_tolerance > 0.0 && params.rank_tolerance < 1.0) {
            return invalid(
                "rank_tolerance",
                format!(
                    "is {}; use a small positive number such as 1e-10",
                    params.rank_tolerance
                ),
            );
        }
        if !params.weight.smooth_at_origin() {
            return invalid(
                "weight",
                format!(
                    "{:?} has a kink or a pole at r = 0, so grad w is undefined at a node; \
                     use poly6, cubic_spline or wendland_c2",
                    params.weight
                ),
            );
        }
        Ok(Self {
            dim,
            params,
            inv_h: 1.0 / params.h,
        })
    }

    /// The dimension (1, 2 or 3) of the basis and of the distances; node
    /// coordinates past it are ignored.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The parameters, as validated by [`Mls::new`].
    pub fn params(&self) -> &MlsParams {
        &self.params
    }

    /// The weight `w = W(r / h)` and its gradient in `x` for a node at
    /// offset `d = x - x_i`, or `None` outside the support (also for
    /// non-finite offsets).
    fn weight(&self, d: &[Real; 3]) -> Option<(Real, [Real; 3])> {
        let r = d[..self.dim].iter().map(|v| v * v).sum::<Real>().sqrt();
        let q = r * self.inv_h;
        // Also false for a NaN distance.
        if q.is_nan() || q >= 1.0 {
            return None;
        }
        let [w, dw_dq, _] = self.params.weight.profile(q);
        if w.is_nan() || w <= 0.0 {
            return None;
        }
        let mut grad = [0.0; 3];
        if r > 0.0 {
            // dw/dx_k = W'(q) / h * d_k / r.
            let scale = dw_dq * self.inv_h / r;
            for k in 0..self.dim {
                grad[k] = scale * d[k];
            }
        }
        Some((w, grad))
    }
}

/// The terms of one node with a positive weight.
#[derive(Debug, Clone, Copy)]
struct NodeTerms {
    /// Index into the caller's node slice.
    index: usize,
    w: Real,
    /// `grad_x w_i`.
    dw: [Real; 3],
    /// `p(s_i)` and `dp/ds_k` at `s_i = (x_i - x) / h`.
    basis: BasisValues,
}

/// Scratch memory of one fit, reused between fits.
#[derive(Debug, Clone)]
struct Scratch {
    nodes: Vec<NodeTerms>,
    moment: Square,
    inverse: Square,
}

impl Default for Scratch {
    fn default() -> Self {
        Self {
            nodes: Vec::new(),
            moment: [0.0; MAX_BASIS * MAX_BASIS],
            inverse: [0.0; MAX_BASIS * MAX_BASIS],
        }
    }
}

impl Scratch {
    /// Collects the nodes with a positive weight around `x`; `weight`
    /// gives node `i`'s weight and its gradient at the offset `x - x_i`.
    fn gather(
        &mut self,
        mls: &Mls,
        x: &Vector,
        nodes: &[Vector],
        weight: impl Fn(usize, &[Real; 3]) -> Option<(Real, [Real; 3])>,
    ) {
        self.nodes.clear();
        for (index, xi) in nodes.iter().enumerate() {
            let d = [x[0] - xi[0], x[1] - xi[1], x[2] - xi[2]];
            if let Some((w, dw)) = weight(index, &d) {
                let s = [-d[0] * mls.inv_h, -d[1] * mls.inv_h, -d[2] * mls.inv_h];
                self.nodes.push(NodeTerms {
                    index,
                    w,
                    dw,
                    basis: BasisValues::new(mls.dim, mls.params.order, &s),
                });
            }
        }
    }

    /// Inverts the gathered nodes' moment matrix at the highest order up
    /// to `mls`'s at which it has full rank (the rank fallback); returns
    /// that order, its basis size and the inversion. `count` is the
    /// caller's node count, for the error.
    fn fit(
        &mut self,
        mls: &Mls,
        x: &Vector,
        count: usize,
    ) -> Result<(Order, usize, Inversion), MlsError> {
        let no_support = || MlsError::NoSupport {
            at: [x[0], x[1], x[2]],
            nodes: count,
            h: mls.params.h,
        };
        if self.nodes.is_empty() {
            return Err(no_support());
        }
        let mut order = mls.params.order;
        loop {
            let n = order.basis_size(mls.dim);
            let inversion = self.invert_moment(0, n, mls.params.rank_tolerance);
            if inversion.rank == n {
                return Ok((order, n, inversion));
            }
            order = order.lower().ok_or_else(no_support)?;
        }
    }

    /// Builds `sum_i w_i p_i p_i^T` over the basis entries
    /// `first..first + n` and pseudo-inverts it into `self.inverse`.
    fn invert_moment(&mut self, first: usize, n: usize, tolerance: Real) -> Inversion {
        let m = &mut self.moment;
        m[..n * n].fill(0.0);
        for node in &self.nodes {
            let p = &node.basis.p[first..first + n];
            for a in 0..n {
                let wa = node.w * p[a];
                for b in a..n {
                    m[a * n + b] += wa * p[b];
                }
            }
        }
        for a in 0..n {
            for b in 0..a {
                m[a * n + b] = m[b * n + a];
            }
        }
        pseudo_inverse(n, m, tolerance, &mut self.inverse)
    }
}

#[cfg(test)]
mod tests;
