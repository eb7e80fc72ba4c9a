//! MLS shape functions and their gradients in the centred, scaled basis.
//!
//! With `s_i = (x_i - x) / h`, `p_i = p(s_i)`, `M = sum_j w_j p_j p_j^T`
//! and `c = M^-1 p(0)`, Eq. 29 reads `phi_i = w_i c . p_i`. The tutorial's
//! Eq. 30-31 differentiate the uncentred form; in the centred form `p(0)`
//! is constant, so only `w_i`, `p_i` and `c` depend on `x`:
//!
//! ```text
//! d p_i / d x_k   = -(1/h) dp/ds_k (s_i)
//! d M / d x_k     = sum_j [ dw_j/dx_k p_j p_j^T + w_j (dp_j/dx_k p_j^T + p_j dp_j/dx_k^T) ]
//! d c / d x_k     = -M^-1 (dM/dx_k) c                       (Eq. 31)
//! d phi_i / d x_k = dw_i/dx_k c.p_i + w_i (dc/dx_k).p_i + w_i c.(dp_i/dx_k)
//! ```
//!
//! `(dM/dx_k) c` is accumulated as a vector, node by node, without forming
//! `dM/dx_k`. The tests check the result against central differences.

use super::{Fit, Mls, MlsError, Scratch};
use crate::math::{Real, Vector};

/// Shape functions `phi_i(x)` and gradients `grad phi_i(x)` of one fit,
/// one entry per node passed to [`Mls::shape_functions`] (zero for nodes
/// outside the support), and the scratch memory reused between fits.
#[derive(Debug, Clone, Default)]
pub struct ShapeFunctions {
    values: Vec<Real>,
    gradients: Vec<Vector>,
    scratch: Scratch,
}

impl ShapeFunctions {
    /// Empty results and scratch, to pass to [`Mls::shape_functions`]
    /// and reuse across fits.
    pub fn new() -> Self {
        Self::default()
    }

    /// `phi_i(x)`: `<f>(x) = sum_i phi_i f_i` (Eq. 26).
    pub fn values(&self) -> &[Real] {
        &self.values
    }

    /// `grad phi_i(x)`: `<grad f>(x) = sum_i f_i grad phi_i` (Eq. 32);
    /// components past the dimension are zero.
    pub fn gradients(&self) -> &[Vector] {
        &self.gradients
    }

    /// `sum_i phi_i f_i`.
    pub fn interpolate(&self, f: &[Real]) -> Real {
        self.values.iter().zip(f).map(|(p, f)| p * f).sum()
    }

    /// `sum_i f_i grad phi_i`.
    pub fn gradient(&self, f: &[Real]) -> Vector {
        self.gradients.iter().zip(f).map(|(g, f)| g * *f).sum()
    }
}

impl Mls {
    /// Shape functions and their gradients at `x` for the sample positions
    /// `nodes` (usually the neighbours of `x`), written to `out`. The
    /// order drops where the moment matrix is rank-deficient; the returned
    /// [`Fit`] says which order was used. Sequential; allocates only while
    /// `out` grows to the largest node count seen.
    ///
    /// # Errors
    /// [`MlsError::NoSupport`] when no node lies within `h` of `x` (or `x`
    /// is not finite); `out` then holds zeros.
    pub fn shape_functions(
        &self,
        x: &Vector,
        nodes: &[Vector],
        out: &mut ShapeFunctions,
    ) -> Result<Fit, MlsError> {
        self.shape_functions_weighted(x, nodes, |_, d| self.weight(d), out)
    }

    /// [`Mls::shape_functions`] with each node's weight given by the
    /// caller: `weight(i, &(x - x_i))` returns node `i`'s weight and its
    /// gradient in `x`, or `None` outside its support. The Element-Free
    /// Galerkin solids use it for their tensor-product weights
    /// ([`crate::approx::tensor`]), whose supports differ from node to node
    /// (Guo–Qin, Section 4.1.1); the parameters' `h` is then only the
    /// basis scale (Eq. 28), and their `weight` is not read.
    ///
    /// # Errors
    /// As [`Mls::shape_functions`], with `h` in the message the basis
    /// scale.
    pub fn shape_functions_weighted(
        &self,
        x: &Vector,
        nodes: &[Vector],
        weight: impl Fn(usize, &[Real; 3]) -> Option<(Real, [Real; 3])>,
        out: &mut ShapeFunctions,
    ) -> Result<Fit, MlsError> {
        out.values.clear();
        out.values.resize(nodes.len(), 0.0);
        out.gradients.clear();
        out.gradients.resize(nodes.len(), Vector::zeros());
        let s = &mut out.scratch;
        s.gather(self, x, nodes, weight);
        let (order, n, inversion) = s.fit(self, x, nodes.len())?;
        let inv = &s.inverse;
        // c = M^-1 p(0) = M^-1 e_0, the first column of the inverse.
        let mut c = [0.0; super::MAX_BASIS];
        for a in 0..n {
            c[a] = inv[a * n];
        }
        let dot = |u: &[Real], v: &[Real]| -> Real {
            u[..n].iter().zip(&v[..n]).map(|(a, b)| a * b).sum()
        };
        let dim = self.dim;
        let inv_h = self.inv_h;
        // (dM/dx_k) c for each k.
        let mut dm_c = [[0.0; super::MAX_BASIS]; 3];
        for node in &s.nodes {
            let p = &node.basis.p;
            let pc = dot(p, &c);
            for (k, dm_c) in dm_c.iter_mut().enumerate().take(dim) {
                let dp = &node.basis.dp[k];
                let dpc = dot(dp, &c);
                // dp_j/dx_k = -(1/h) dp/ds_k.
                for a in 0..n {
                    dm_c[a] += node.dw[k] * pc * p[a] - node.w * inv_h * (dp[a] * pc + p[a] * dpc);
                }
            }
        }
        // dc/dx_k = -M^-1 (dM/dx_k) c.
        let mut dc = [[0.0; super::MAX_BASIS]; 3];
        for k in 0..dim {
            for a in 0..n {
                dc[k][a] = -(0..n).map(|b| inv[a * n + b] * dm_c[k][b]).sum::<Real>();
            }
        }
        for node in &s.nodes {
            let p = &node.basis.p;
            let pc = dot(p, &c);
            out.values[node.index] = node.w * pc;
            let g = &mut out.gradients[node.index];
            for k in 0..dim {
                g[k] = node.dw[k] * pc + node.w * dot(&dc[k], p)
                    - node.w * inv_h * dot(&node.basis.dp[k], &c);
            }
        }
        Ok(Fit {
            order,
            condition: inversion.condition,
            support: s.nodes.len(),
        })
    }
}
