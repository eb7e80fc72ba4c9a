//! The implicit integrator's Newton matrix assembled and solved by sparse
//! Cholesky, for bodies (slender ones in bending above all) where
//! conjugate gradients converge too slowly.
//!
//! `H = M + dt^2 Hess U + dt D` is exact at the current stress states,
//! assembled in `dim x dim` blocks over the free particles only (anchored
//! rows and columns are removed, and a 2D body's constant `z` is left
//! out, so `H` is not singular):
//!
//! - **elastic and volume**: `U_i = V_i W(F_i)` with `F_i = I + sum_e (x_j -
//!   x_i - X_ij) g_e^T`, so `dF_i/dx_n = e_a c_n^T` with `c_n = g_e` for a
//!   neighbour `n = j` and `c_i = -sum_j g_ij`, and
//!   `d^2 U_i / dx_(n,a) dx_(m,b) = V_i (dP[e_a c_n^T] c_m)_b` with `dP` the
//!   exact derivative of the first Piola stress (`material.rs`);
//! - **hourglass**: `U_h,i = kappa_i / 2 sum_e w~_e |e_e|^2` is quadratic in
//!   `x`: each edge error is `e_e = sum_n alpha_n x_n` with `alpha_j += 1`,
//!   `alpha_i -= 1`, `alpha_n -= c_n . X_e`, so block `(m, n)` gains
//!   `kappa_i sum_e w~_e alpha_m alpha_n I`;
//! - **damping**: each edge `(i -> j)` adds `c_e [[I, -I], [-I, I]]` on
//!   `(i, j)`, `c_e = alpha m_i w~_e` (`forces.rs`).
//!
//! Each block column `n` gathers its blocks from the particles `i` whose
//! neighbourhood holds `n` (the edges ending at `n`), so columns are
//! assembled in parallel without locks. The matrix is stored as the lower
//! triangle of full block columns (the diagonal block whole; the
//! factorisation reads only its lower part). The pattern and the fill-
//! reducing ordering depend only on the topology and the anchors, so they
//! are computed once and reused until either changes.

use super::elastic::ElasticSolid;
use crate::math::{Real, Vector};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Side};
use nalgebra::Matrix3;
use rayon::prelude::*;
use std::sync::Arc;

/// Marks an anchored particle in [`Pattern::index`].
const ANCHORED: u32 = u32::MAX;

/// The sparsity of `H` over the free particles and its symbolic
/// factorisation.
#[derive(Debug)]
struct Pattern {
    dim: usize,
    /// The neighbour lists and anchors it was built for: a plastic re-base
    /// or new anchors invalidate it.
    edges: Vec<u32>,
    fixed: Vec<bool>,
    /// Each particle's place among the free ones, or [`ANCHORED`].
    index: Vec<u32>,
    /// The free particles in that order.
    free: Vec<u32>,
    /// Block rows `m >= n` of each block column `n`, sorted.
    block_offsets: Vec<usize>,
    block_rows: Vec<u32>,
    /// The scalar matrix, compressed sparse columns.
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    symbolic: SymbolicCholesky<u32>,
}

/// The direct solver's state, kept between Newton steps so that neither
/// the symbolic analysis nor the value arrays are redone.
#[derive(Debug, Clone, Default)]
pub(super) struct DirectSolver {
    pattern: Option<Arc<Pattern>>,
    /// `H`'s values in the pattern's order.
    values: Vec<Real>,
    /// The Cholesky factor's values.
    factor: Vec<Real>,
    /// Right-hand side, overwritten by the solution.
    rhs: Vec<Real>,
}

impl DirectSolver {
    /// Bytes held by the last Cholesky factor.
    pub fn factor_bytes(&self) -> usize {
        self.factor.len() * std::mem::size_of::<Real>()
    }
}

impl Pattern {
    /// The pattern of `solid`'s Hessian, or `None` when it is too large
    /// to index with 32 bits or its analysis runs out of memory.
    fn build(solid: &ElasticSolid) -> Option<Self> {
        let dim = solid.params.dim;
        let t = &solid.topology;
        let edges = t.gradients.neighbour_indices();
        let mut index = vec![ANCHORED; solid.len()];
        let mut free = Vec::with_capacity(solid.len());
        for (k, (slot, &fixed)) in index.iter_mut().zip(&solid.fixed).enumerate() {
            if !fixed {
                *slot = free.len() as u32;
                free.push(k as u32);
            }
        }
        let columns: Vec<Vec<u32>> = free
            .par_iter()
            .enumerate()
            .map(|(n, &particle)| {
                let mut rows = Vec::new();
                for &e in t.incoming(particle as usize) {
                    let i = t.owner[e as usize] as usize;
                    for &m in &edges[t.gradients.range(i)] {
                        let m = index[m as usize];
                        if m != ANCHORED && m as usize >= n {
                            rows.push(m);
                        }
                    }
                }
                rows.sort_unstable();
                rows.dedup();
                rows
            })
            .collect();
        let scalars = free.len() * dim;
        let nnz: usize = columns.iter().map(|c| c.len() * dim * dim).sum();
        if u32::try_from(nnz).is_err() || u32::try_from(scalars).is_err() {
            return None;
        }
        let mut block_offsets = Vec::with_capacity(free.len() + 1);
        block_offsets.push(0);
        let mut col_ptr = Vec::with_capacity(scalars + 1);
        col_ptr.push(0u32);
        let mut row_idx = Vec::with_capacity(nnz);
        for rows in &columns {
            block_offsets.push(block_offsets.last().copied().unwrap_or(0) + rows.len());
            for _ in 0..dim {
                for &m in rows {
                    for b in 0..dim {
                        row_idx.push(m * dim as u32 + b as u32);
                    }
                }
                col_ptr.push(row_idx.len() as u32);
            }
        }
        let symbolic = factorize_symbolic_cholesky(
            SymbolicSparseColMatRef::new_checked(scalars, scalars, &col_ptr, None, &row_idx),
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .ok()?;
        Some(Self {
            dim,
            edges: edges.to_vec(),
            fixed: solid.fixed.clone(),
            index,
            free,
            block_offsets,
            block_rows: columns.concat(),
            col_ptr,
            row_idx,
            symbolic,
        })
    }

    /// Whether it still describes `solid`.
    fn matches(&self, solid: &ElasticSolid) -> bool {
        self.dim == solid.params.dim
            && self.fixed == solid.fixed
            && self.edges == solid.topology.gradients.neighbour_indices()
    }
}

impl ElasticSolid {
    /// Solves `H d = -gradient` into `direction` by sparse Cholesky at the
    /// current stress states; returns false, leaving `direction` as it
    /// was, when `H` is not positive definite (the caller falls back to
    /// CG) or the factorisation cannot be had (too large, out of memory).
    pub(super) fn direct_direction(
        &self,
        dt: Real,
        solver: &mut DirectSolver,
        gradient: &[Vector],
        direction: &mut [Vector],
    ) -> bool {
        if !solver.pattern.as_ref().is_some_and(|p| p.matches(self)) {
            solver.pattern = Pattern::build(self).map(Arc::new);
        }
        let Some(pattern) = solver.pattern.clone() else {
            return false;
        };
        let symbolic = &pattern.symbolic;
        // The two large arrays: their allocation failing means CG instead.
        let grow =
            |v: &mut Vec<Real>, len: usize| v.try_reserve(len.saturating_sub(v.len())).is_ok();
        if !grow(&mut solver.values, pattern.row_idx.len())
            || !grow(&mut solver.factor, symbolic.len_val())
        {
            return false;
        }
        self.assemble_hessian(dt, &pattern, &mut solver.values);
        let par = faer::get_global_parallelism();
        let Ok(mut memory) = MemBuffer::try_new(
            symbolic
                .factorize_numeric_llt_scratch::<Real>(par, Default::default())
                .or(symbolic.solve_in_place_scratch::<Real>(1, par)),
        ) else {
            return false;
        };
        solver.factor.resize(symbolic.len_val(), 0.0);
        let n = symbolic.nrows();
        let matrix = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx),
            &solver.values,
        );
        let Ok(llt) = symbolic.factorize_numeric_llt(
            &mut solver.factor,
            matrix,
            Side::Lower,
            LltRegularization::default(),
            par,
            MemStack::new(&mut memory),
            Default::default(),
        ) else {
            return false;
        };
        let dim = pattern.dim;
        solver.rhs.clear();
        for &k in &pattern.free {
            solver
                .rhs
                .extend(gradient[k as usize].iter().take(dim).map(|g| -g));
        }
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut solver.rhs, n, 1),
            par,
            MemStack::new(&mut memory),
        );
        direction.fill(Vector::zeros());
        for (d, &k) in solver.rhs.chunks_exact(dim).zip(&pattern.free) {
            for (out, v) in direction[k as usize].iter_mut().zip(d) {
                *out = *v;
            }
        }
        true
    }

    /// `H`'s values in `pattern`'s order, at the current stress states.
    fn assemble_hessian(&self, dt: Real, pattern: &Pattern, values: &mut Vec<Real>) {
        let dim = pattern.dim;
        values.resize(pattern.row_idx.len(), 0.0);
        let mut columns = Vec::with_capacity(pattern.free.len());
        let mut rest = values.as_mut_slice();
        for w in pattern.block_offsets.windows(2) {
            let (head, tail) = rest.split_at_mut((w[1] - w[0]) * dim * dim);
            columns.push(head);
            rest = tail;
        }
        columns
            .into_par_iter()
            .enumerate()
            .for_each(|(n, out)| self.assemble_column(dt, pattern, n, out));
    }

    /// Block column `n` of `H` into `out`, laid out `[a][row block][b]` for
    /// the entry `H_(m b),(n a)`.
    fn assemble_column(&self, dt: Real, pattern: &Pattern, n: usize, out: &mut [Real]) {
        out.fill(0.0);
        let dim = pattern.dim;
        let rows = &pattern.block_rows[pattern.block_offsets[n]..pattern.block_offsets[n + 1]];
        let len = rows.len();
        let at = |slot: usize, a: usize, b: usize| (a * len + slot) * dim + b;
        let slot_of = |m: u32| rows.binary_search(&m).ok();
        let model = self.model();
        let t = &self.topology;
        let edges = t.gradients.neighbour_indices();
        let g = t.gradients.all_weights();
        let states = &self.scratch.states;
        let dt2 = dt * dt;
        let pn = pattern.free[n] as usize;

        for &e_n in t.incoming(pn) {
            let e_n = e_n as usize;
            let i = t.owner[e_n] as usize;
            // `c` of the node an edge of `i` ends at.
            let c = |e: usize| {
                if edges[e] as usize == i {
                    g[e] - t.sum_g[i]
                } else {
                    g[e]
                }
            };
            let c_n = c(e_n);
            let volume = model.volumes[i] * dt2;
            let mut piola = [Matrix3::zeros(); 3];
            for (a, p) in piola.iter_mut().enumerate().take(dim) {
                let mut df = Matrix3::zeros();
                df.set_row(a, &c_n.transpose());
                *p = model.material.first_piola_derivative(&states[i], &df) * volume;
            }
            // Hourglass: `beta_e = w~_e alpha_n(e)`, summed plainly and
            // against `X_e`, give `sum_e w~_e alpha_n alpha_m` for any `m`
            // in O(1).
            let kappa = model.hourglass * model.volumes[i] * dt2;
            let beta = |e: usize| {
                let own = if e == e_n { 1.0 } else { 0.0 } - if pn == i { 1.0 } else { 0.0 };
                t.pair_weight[e] * (own - c_n.dot(&t.rest_offset[e]))
            };
            let (beta_sum, beta_x) = if kappa > 0.0 {
                t.gradients
                    .range(i)
                    .fold((0.0, Vector::zeros()), |(s, x), e| {
                        let b = beta(e);
                        (s + b, x + t.rest_offset[e] * b)
                    })
            } else {
                (0.0, Vector::zeros())
            };
            for e_m in t.gradients.range(i) {
                let m = edges[e_m] as usize;
                let Some(slot) = slot_of(pattern.index[m]) else {
                    // Anchored, or above the diagonal.
                    continue;
                };
                let c_m = c(e_m);
                for (a, p) in piola.iter().enumerate().take(dim) {
                    let column = p * c_m;
                    for b in 0..dim {
                        out[at(slot, a, b)] += column[b];
                    }
                }
                if kappa > 0.0 {
                    let own = if m == i { beta_sum } else { 0.0 };
                    let s = kappa * (beta(e_m) - own - c_m.dot(&beta_x));
                    for a in 0..dim {
                        out[at(slot, a, a)] += s;
                    }
                }
            }
        }

        // The diagonal block is the first: every other row is below it.
        let mut diagonal = self.masses[pn];
        if model.damping > 0.0 {
            let pairs = t
                .gradients
                .range(pn)
                .map(|e| (edges[e] as usize, self.masses[pn], e))
                .chain(t.incoming(pn).iter().map(|&e| {
                    let i = t.owner[e as usize] as usize;
                    (i, self.masses[i], e as usize)
                }));
            for (other, mass, e) in pairs {
                if other == pn {
                    continue;
                }
                let c = dt * model.damping * mass * t.pair_weight[e];
                diagonal += c;
                if let Some(slot) = slot_of(pattern.index[other]) {
                    for a in 0..dim {
                        out[at(slot, a, a)] -= c;
                    }
                }
            }
        }
        for a in 0..dim {
            out[at(0, a, a)] += diagonal;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approx::mls::Order;
    use crate::geometry::Shape;
    use crate::solid::{Integrator, Material, Obstacles, SolidParams};

    /// A deterministic pseudo-random number in [-1, 1).
    fn noise(seed: &mut u64) -> Real {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as Real / (1u64 << 52) as Real - 1.0
    }

    /// A bent, damped block with volume and hourglass terms and its left
    /// end anchored.
    fn bent(dim: usize) -> ElasticSolid {
        let spacing = 0.1;
        let young = 1e5;
        let p = SolidParams {
            dim,
            spacing,
            density: 1000.0,
            young,
            material: Material::from_young_poisson(young, 0.3, 3e4),
            order: Order::Linear,
            support: 2.0 * spacing,
            hourglass: 0.5,
            damping: 5.0,
            friction: 0.0,
            integrator: Integrator::Explicit { cfl: 0.5 },
            plasticity: None,
        };
        let rest = Shape::Box {
            half_extents: Vector::new(0.4, 0.2, 0.2),
        }
        .sample_volume(spacing, dim)
        .expect("samples");
        let n = rest.len();
        let fixed = rest.iter().map(|x| x.x < -0.3).collect();
        let mut solid = ElasticSolid::new(
            p,
            rest,
            vec![Vector::zeros(); n],
            fixed,
            Obstacles::default(),
        )
        .expect("solid");
        let x = solid
            .rest_positions()
            .iter()
            .map(|x| {
                Vector::new(
                    x.x + 0.1 * x.y * x.y,
                    x.y + 0.05 * x.x * x.y,
                    x.z + 0.08 * x.x * x.z,
                )
            })
            .collect();
        solid
            .set_state(x, vec![Vector::zeros(); n])
            .expect("same length");
        // The stress states the Hessian linearises about.
        solid.internal_forces(None, None, false);
        solid
    }

    /// `H p` from the stored lower triangle, over the free particles.
    fn product(pattern: &Pattern, values: &[Real], p: &[Vector]) -> Vec<Vector> {
        let dim = pattern.dim;
        let x: Vec<Real> = pattern
            .free
            .iter()
            .flat_map(|&k| p[k as usize].iter().take(dim).copied().collect::<Vec<_>>())
            .collect();
        let mut y = vec![0.0; x.len()];
        for col in 0..x.len() {
            let range = pattern.col_ptr[col] as usize..pattern.col_ptr[col + 1] as usize;
            for (&row, &v) in pattern.row_idx[range.clone()].iter().zip(&values[range]) {
                let row = row as usize;
                if row > col {
                    y[row] += v * x[col];
                    y[col] += v * x[row];
                } else if row == col {
                    y[row] += v * x[col];
                }
            }
        }
        let mut out = vec![Vector::zeros(); p.len()];
        for (chunk, &k) in y.chunks_exact(dim).zip(&pattern.free) {
            for (o, v) in out[k as usize].iter_mut().zip(chunk) {
                *o = *v;
            }
        }
        out
    }

    fn relative_difference(a: &[Vector], b: &[Vector], dim: usize) -> Real {
        let diff: Real = a
            .iter()
            .zip(b)
            .map(|(a, b)| (a - b).rows(0, dim).norm_squared())
            .sum();
        let scale: Real = b.iter().map(|b| b.rows(0, dim).norm_squared()).sum();
        (diff / scale).sqrt()
    }

    #[test]
    fn assembled_hessian_matches_the_matrix_free_product_and_solves() {
        for dim in [2, 3] {
            let solid = bent(dim);
            // Long enough that stiffness outweighs mass in `H`.
            let dt = 0.05;
            let pattern = Pattern::build(&solid).expect("pattern");
            let mut values = Vec::new();
            solid.assemble_hessian(dt, &pattern, &mut values);
            let mut seed = 7;
            let p: Vec<Vector> = (0..solid.len())
                .map(|k| {
                    let mut v = Vector::new(noise(&mut seed), noise(&mut seed), noise(&mut seed));
                    if dim == 2 {
                        v.z = 0.0;
                    }
                    if solid.fixed[k] { Vector::zeros() } else { v }
                })
                .collect();
            let assembled = product(&pattern, &values, &p);
            let matrix_free = solid.hessian_product(dt, &p);
            let error = relative_difference(&assembled, &matrix_free, dim);
            assert!(error < 1e-8, "{dim}D: H p differs by {error:e}");

            // The solve inverts the matrix-free operator.
            let mut solver = DirectSolver::default();
            let rhs: Vec<Vector> = matrix_free.iter().map(|v| -v).collect();
            let mut direction = vec![Vector::zeros(); solid.len()];
            assert!(solid.direct_direction(dt, &mut solver, &rhs, &mut direction));
            let error = relative_difference(&direction, &p, dim);
            assert!(error < 1e-8, "{dim}D: solution differs by {error:e}");
            assert!(solver.factor_bytes() > 0);
        }
    }
}
