//! Galerkin assembly of the mass and stiffness matrices, the gravity
//! load and the penalty for fixed regions (Guo–Qin, Sections 4.1.2 and
//! 5.1), over the node pairs that share a quadrature point.
//!
//! With shape functions `phi_I` and the linear isotropic material of Lamé
//! parameters `lambda`, `mu`:
//!
//! ```text
//! M_(Ia)(Jb) = delta_ab  int rho phi_I phi_J                      (Eq. 16-17)
//! K_(Ia)(Jb) = int lambda phi_I,a phi_J,b + mu phi_I,b phi_J,a
//!                  + mu delta_ab grad phi_I . grad phi_J          (B^T D B)
//! f_(Ia)     = int rho phi_I g_a
//! ```
//!
//! **Essential boundary conditions by penalty.** MLS shape functions do
//! not interpolate (`u(x_I) != u_I`, Section 5.3.3), so a fixed node cannot
//! simply be removed. The penalty method adds
//! `beta int_(Gamma_u) phi_I phi_J delta_ab` over the fixed part of the
//! surface, which keeps the system symmetric positive definite and its
//! size unchanged (Lagrange multipliers would make it indefinite and grow
//! it, and the modal analysis needs K and M alone). `beta` is
//! `penalty * E / cell`: the constraint's error falls as `1 / penalty`
//! while the conditioning grows with it; the tests measure both ends.

use super::shape::ShapeTable;
use crate::cancel::{Cancel, Cancelled};
use crate::linalg::{BlockColumn, BlockPattern};
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// The Lamé parameters `(lambda, mu)` of Young's modulus `e` and Poisson's
/// ratio `nu`.
pub fn lame(e: Real, nu: Real) -> (Real, Real) {
    (
        e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        e / (2.0 * (1.0 + nu)),
    )
}

/// A shape table with a weight per point and, per node, the points that
/// reach it: one integral over a point set.
#[derive(Debug, Clone)]
pub struct Integral {
    /// The rows.
    pub table: ShapeTable,
    /// The weight of each point (volume, or area on the surface).
    pub weights: Vec<Real>,
    by_node_offsets: Vec<u32>,
    by_node: Vec<u32>,
}

impl Integral {
    /// The integral over `table`'s points with `weights`, for `nodes`
    /// nodes.
    pub fn new(table: ShapeTable, weights: Vec<Real>, nodes: usize) -> Self {
        let (by_node_offsets, by_node) = table.points_by_node(nodes);
        Self {
            table,
            weights,
            by_node_offsets,
            by_node,
        }
    }

    /// The points whose rows hold node `n`.
    pub(super) fn points_of(&self, n: usize) -> &[u32] {
        &self.by_node[self.by_node_offsets[n] as usize..self.by_node_offsets[n + 1] as usize]
    }

    /// Calls `f(m_slot_entry, q, i_n, i_m)` for each point `q` reaching
    /// node `n` and each node `m >= n` of its row (`i_n`, `i_m` their
    /// places in the row).
    fn pairs(&self, n: usize, mut f: impl FnMut(usize, usize, usize, u32)) {
        for &q in self.points_of(n) {
            let q = q as usize;
            let row = self.table.row(q);
            let Ok(i_n) = row.nodes.binary_search(&(n as u32)) else {
                continue;
            };
            for (i_m, &m) in row.nodes.iter().enumerate().skip(i_n) {
                f(q, i_n, i_m, m);
            }
        }
    }
}

/// The block rows `m >= n` of each block column `n` that the integrals
/// couple: the sparsity of M and K (`None` when too large to index).
/// Reads `cancel` once per column.
///
/// # Errors
/// [`Cancelled`] once `cancel` is raised.
pub fn pattern(
    nodes: usize,
    integrals: &[&Integral],
    cancel: &Cancel,
) -> Result<Option<BlockPattern>, Cancelled> {
    let columns: Vec<Vec<u32>> = (0..nodes)
        .into_par_iter()
        .map(|n| {
            cancel.check()?;
            let mut rows = vec![n as u32];
            for integral in integrals {
                integral.pairs(n, |_, _, _, m| rows.push(m));
            }
            rows.sort_unstable();
            rows.dedup();
            Ok(rows)
        })
        .collect::<Result<_, Cancelled>>()?;
    Ok(BlockPattern::new(3, &columns))
}

/// Adds column `n` of the stiffness `K` (volume integral) to `out`.
pub fn stiffness_column(
    volume: &Integral,
    (lambda, mu): (Real, Real),
    n: usize,
    out: &mut BlockColumn<'_>,
) {
    volume.pairs(n, |q, i_n, i_m, m| {
        let Some(slot) = out.slot(m) else { return };
        let row = volume.table.row(q);
        let w = volume.weights[q];
        let (gn, gm) = (row.gradients[i_n], row.gradients[i_m]);
        let dot = gm.dot(&gn);
        for a in 0..3 {
            for b in 0..3 {
                let mut v = lambda * gm[b] * gn[a] + mu * gm[a] * gn[b];
                if a == b {
                    v += mu * dot;
                }
                out.add(slot, a, b, w * v);
            }
        }
    });
}

/// Adds column `n` of `scale * int phi_I phi_J delta_ab` over `integral`
/// to `out`: the consistent mass (`scale = rho`) or the penalty
/// (`scale = beta`).
pub fn product_column(integral: &Integral, scale: Real, n: usize, out: &mut BlockColumn<'_>) {
    integral.pairs(n, |q, i_n, i_m, m| {
        let Some(slot) = out.slot(m) else { return };
        let row = integral.table.row(q);
        let v = scale * integral.weights[q] * row.values[i_n] * row.values[i_m];
        for a in 0..3 {
            out.add(slot, a, a, v);
        }
    });
}

/// `int rho phi_I` for each node: the row sums of the consistent mass
/// (the shape functions sum to one), its lumped form, and the weight of
/// each node in a body load.
pub fn node_masses(volume: &Integral, density: Real, nodes: usize) -> Vec<Real> {
    (0..nodes)
        .into_par_iter()
        .map(|n| {
            volume
                .points_of(n)
                .iter()
                .map(|&q| {
                    let q = q as usize;
                    let row = volume.table.row(q);
                    let i = row.nodes.binary_search(&(n as u32)).unwrap_or(0);
                    density * volume.weights[q] * row.values[i]
                })
                .sum()
        })
        .collect()
}

/// The load of a uniform acceleration `g` on nodes of masses `masses`
/// (from [`node_masses`]), as a flat `3 n` vector.
pub fn body_load(masses: &[Real], g: &Vector) -> Vec<Real> {
    masses
        .iter()
        .flat_map(|m| [g[0] * m, g[1] * m, g[2] * m])
        .collect()
}
