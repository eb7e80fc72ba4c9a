//! MLS shape functions with their second derivatives, in the centred,
//! scaled basis of `shape.rs`: what a thin shell's bending energy reads
//! (Guo–Qin Section 5.2, curvatures from the second derivatives of the
//! middle surface's map; the tutorial's Eq. 34 takes second derivatives
//! of the approximation by the same repeated chain rule).
//!
//! With `phi_i = w_i c . p_i`, `c = M^-1 p(0)` and `M c = e_0` (see
//! `shape.rs`), differentiating `M c = e_0` twice gives, with `_k` for
//! `d/dx_k` and `P_ik = dp_i/dx_k = -(1/h) dp/ds_k`,
//! `P_ikl = (1/h^2) d^2 p/ds_k ds_l`:
//!
//! ```text
//! c_k  = -M^-1 (M_k c)
//! c_kl = -M^-1 (M_kl c + M_k c_l + M_l c_k)
//! M_k  = sum_j [ w_j,k p_j p_j^T + w_j (P_jk p_j^T + p_j P_jk^T) ]
//! M_kl = sum_j [ w_j,kl p_j p_j^T + w_j,k (P_jl p_j^T + p_j P_jl^T) + w_j,l (P_jk p_j^T + p_j P_jk^T)
//!              + w_j (P_jkl p_j^T + P_jk P_jl^T + P_jl P_jk^T + p_j P_jkl^T) ]
//! phi_i,kl = w_i,kl c.p_i + w_i,k (c_l.p_i + c.P_il) + w_i,l (c_k.p_i + c.P_ik)
//!          + w_i (c_kl.p_i + c_k.P_il + c_l.P_ik + c.P_ikl)
//! ```
//!
//! Each matrix-vector product is accumulated node by node, without
//! forming `M_k` or `M_kl`. The tests check the second derivatives
//! against central differences of the gradients, and that a quadratic
//! basis reproduces the second derivatives of every quadratic field.

use super::{Fit, Mls, MlsError, Order, Scratch};
use crate::approx::tensor::WeightHessian;
use crate::math::{Real, Vector};
use nalgebra::Matrix3;

/// Shape functions, gradients and Hessians of one fit, one entry per node
/// passed to [`Mls::shape_hessians_weighted`] (zero for nodes outside the
/// support); rows and columns past the dimension are zero.
#[derive(Debug, Clone, Default)]
pub struct ShapeHessians {
    values: Vec<Real>,
    gradients: Vec<Vector>,
    hessians: Vec<Matrix3<Real>>,
    /// Each supporting node's weight Hessian, in the order of the
    /// scratch's nodes.
    weight_hessians: Vec<[[Real; 3]; 3]>,
    /// Each supporting node's basis derivatives `P_k = dp_i/dx_k`, same
    /// order, formed once per fit.
    basis_slopes: Vec<[[Real; super::MAX_BASIS]; 3]>,
    scratch: Scratch,
}

impl ShapeHessians {
    /// Empty results and scratch, reused across fits.
    pub fn new() -> Self {
        Self::default()
    }

    /// `phi_i(x)`.
    pub fn values(&self) -> &[Real] {
        &self.values
    }

    /// `grad phi_i(x)`.
    pub fn gradients(&self) -> &[Vector] {
        &self.gradients
    }

    /// The Hessian of `phi_i` at `x`: `<d^2 f / dx_k dx_l>(x) = sum_i f_i
    /// H_i[(k, l)]`.
    pub fn hessians(&self) -> &[Matrix3<Real>] {
        &self.hessians
    }

    /// `sum_i f_i H_i`: the approximation's Hessian of the samples `f`.
    pub fn hessian(&self, f: &[Real]) -> Matrix3<Real> {
        self.hessians.iter().zip(f).map(|(h, f)| h * *f).sum()
    }
}

/// The basis' second derivatives `d^2 p / ds_k ds_l`, constant: only the
/// quadratic monomials `s_a s_b` have any (`delta_ak delta_bl + delta_al
/// delta_bk`).
fn basis_curvature(dim: usize, order: Order) -> [[[Real; super::MAX_BASIS]; 3]; 3] {
    let mut dd = [[[0.0; super::MAX_BASIS]; 3]; 3];
    if order >= Order::Quadratic {
        // The monomials s_a s_b (a <= b) follow the 1 + dim of lower
        // degree, in this order (`basis.rs`).
        let pairs = (0..dim).flat_map(|a| (a..dim).map(move |b| (a, b)));
        for (n, (a, b)) in (1 + dim..).zip(pairs) {
            dd[a][b][n] += 1.0;
            dd[b][a][n] += 1.0;
        }
    }
    dd
}

impl Mls {
    /// Shape functions, gradients and Hessians at `x` for the sample
    /// positions `nodes`, each node's weight given by the caller:
    /// `weight(i, &(x - x_i))` returns node `i`'s weight with its gradient
    /// and Hessian in `x` (e.g. [`crate::approx::tensor::tensor_weight_hessian`]),
    /// or `None` outside its support; the parameters' `h` is the basis
    /// scale only. The order drops where the moment matrix is
    /// rank-deficient, as in [`Mls::shape_functions`], and the returned
    /// [`Fit`] says which was used.
    ///
    /// # Errors
    /// [`MlsError::NoSupport`] when no node has a positive weight at `x`;
    /// `out` then holds zeros.
    pub fn shape_hessians_weighted(
        &self,
        x: &Vector,
        nodes: &[Vector],
        weight: impl Fn(usize, &[Real; 3]) -> Option<WeightHessian>,
        out: &mut ShapeHessians,
    ) -> Result<Fit, MlsError> {
        let count = nodes.len();
        out.values.clear();
        out.values.resize(count, 0.0);
        out.gradients.clear();
        out.gradients.resize(count, Vector::zeros());
        out.hessians.clear();
        out.hessians.resize(count, Matrix3::zeros());
        let s = &mut out.scratch;
        s.gather(self, x, nodes, |i, d| weight(i, d).map(|(w, g, _)| (w, g)));
        out.weight_hessians.clear();
        for node in &s.nodes {
            let xi = &nodes[node.index];
            let d = [x[0] - xi[0], x[1] - xi[1], x[2] - xi[2]];
            // The same call that admitted the node in `gather`.
            let (_, _, h) = weight(node.index, &d).unwrap_or((0.0, [0.0; 3], [[0.0; 3]; 3]));
            out.weight_hessians.push(h);
        }
        let (order, n, inversion) = s.fit(self, x, count)?;
        let (dim, inv_h) = (self.dim, self.inv_h);
        let inv = &s.inverse;
        let neg_solve = |v: &[Real; super::MAX_BASIS]| {
            let mut out = [0.0; super::MAX_BASIS];
            for a in 0..n {
                out[a] = -(0..n).map(|b| inv[a * n + b] * v[b]).sum::<Real>();
            }
            out
        };
        let dot = |u: &[Real], v: &[Real]| -> Real {
            u[..n].iter().zip(&v[..n]).map(|(a, b)| a * b).sum()
        };
        // The x-derivatives of the nodes' bases: P_k per node, P_kl (the
        // same for every node).
        out.basis_slopes.clear();
        out.basis_slopes.extend(s.nodes.iter().map(|node| {
            let mut pk = [[0.0; super::MAX_BASIS]; 3];
            for (pk, dp) in pk.iter_mut().zip(&node.basis.dp).take(dim) {
                for (out, d) in pk.iter_mut().zip(dp).take(n) {
                    *out = -inv_h * d;
                }
            }
            pk
        }));
        let mut pkl_all = basis_curvature(dim, order);
        for row in &mut pkl_all {
            for entry in row.iter_mut() {
                for v in entry.iter_mut() {
                    *v *= inv_h * inv_h;
                }
            }
        }
        let slopes = &out.basis_slopes;

        let mut c = [0.0; super::MAX_BASIS];
        for a in 0..n {
            c[a] = inv[a * n];
        }
        // M_k c, then c_k.
        let mut dm_c = [[0.0; super::MAX_BASIS]; 3];
        for (node, pks) in s.nodes.iter().zip(slopes) {
            let p = &node.basis.p;
            let pc = dot(p, &c);
            for (k, acc) in dm_c.iter_mut().enumerate().take(dim) {
                let pk = &pks[k];
                let pkc = dot(pk, &c);
                for a in 0..n {
                    acc[a] += node.dw[k] * pc * p[a] + node.w * (pk[a] * pc + p[a] * pkc);
                }
            }
        }
        let mut dc = [[0.0; super::MAX_BASIS]; 3];
        for k in 0..dim {
            dc[k] = neg_solve(&dm_c[k]);
        }
        // M_kl c + M_k c_l + M_l c_k, then c_kl (k <= l).
        let mut ddc = [[[0.0; super::MAX_BASIS]; 3]; 3];
        for k in 0..dim {
            for l in k..dim {
                let pkl = &pkl_all[k][l];
                let mut v = [0.0; super::MAX_BASIS];
                for ((node, wh), pks) in s.nodes.iter().zip(&out.weight_hessians).zip(slopes) {
                    let p = &node.basis.p;
                    let (pk, pl) = (&pks[k], &pks[l]);
                    let (pc, pkc, plc, pklc) = (dot(p, &c), dot(pk, &c), dot(pl, &c), dot(pkl, &c));
                    let (pcl, pkcl) = (dot(p, &dc[l]), dot(pk, &dc[l]));
                    let (pck, plck) = (dot(p, &dc[k]), dot(pl, &dc[k]));
                    let (w, wk, wl, wkl) = (node.w, node.dw[k], node.dw[l], wh[k][l]);
                    for a in 0..n {
                        // M_kl c
                        v[a] += wkl * p[a] * pc
                            + wk * (pl[a] * pc + p[a] * plc)
                            + wl * (pk[a] * pc + p[a] * pkc)
                            + w * (pkl[a] * pc + pk[a] * plc + pl[a] * pkc + p[a] * pklc);
                        // M_k c_l
                        v[a] += wk * p[a] * pcl + w * (pk[a] * pcl + p[a] * pkcl);
                        // M_l c_k
                        v[a] += wl * p[a] * pck + w * (pl[a] * pck + p[a] * plck);
                    }
                }
                ddc[k][l] = neg_solve(&v);
                ddc[l][k] = ddc[k][l];
            }
        }
        for ((node, wh), pk_all) in s.nodes.iter().zip(&out.weight_hessians).zip(slopes) {
            let p = &node.basis.p;
            let pc = dot(p, &c);
            let i = node.index;
            out.values[i] = node.w * pc;
            for k in 0..dim {
                out.gradients[i][k] =
                    node.dw[k] * pc + node.w * (dot(&dc[k], p) + dot(&c, &pk_all[k]));
            }
            for k in 0..dim {
                for l in k..dim {
                    let (pk, pl) = (&pk_all[k], &pk_all[l]);
                    let pkl = &pkl_all[k][l];
                    let value = wh[k][l] * pc
                        + node.dw[k] * (dot(&dc[l], p) + dot(&c, pl))
                        + node.dw[l] * (dot(&dc[k], p) + dot(&c, pk))
                        + node.w
                            * (dot(&ddc[k][l], p)
                                + dot(&dc[k], pl)
                                + dot(&dc[l], pk)
                                + dot(&c, pkl));
                    out.hessians[i][(k, l)] = value;
                    out.hessians[i][(l, k)] = value;
                }
            }
        }
        Ok(Fit {
            order,
            condition: inversion.condition,
            support: s.nodes.len(),
        })
    }
}

#[cfg(test)]
mod tests;
