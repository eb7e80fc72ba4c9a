//! Symmetric matrices in `dim x dim` blocks: the sparsity pattern and its
//! symbolic Cholesky analysis, assembly by block columns in parallel, and
//! faer's sparse Cholesky factorisation and solve.
//!
//! The matrix is stored as the lower triangle of full block columns (the
//! diagonal block whole; the factorisation reads only its lower part), in
//! compressed sparse columns of scalars. A block column `n` holds the
//! block rows `m >= n` its caller names, sorted, the diagonal first; its
//! values are laid out `[a][row block][b]` for the entry `A_(m b),(n a)`,
//! so that each block column is one contiguous slice and columns assemble
//! in parallel without locks. The pattern and its fill-reducing ordering
//! (approximate minimum degree) are computed once and reused for every
//! matrix with that sparsity.

use crate::math::Real;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Side};
use rayon::prelude::*;

/// The sparsity of a symmetric block matrix and its symbolic
/// factorisation.
#[derive(Debug)]
pub struct BlockPattern {
    dim: usize,
    /// Block rows `m >= n` of each block column `n`, sorted.
    block_offsets: Vec<usize>,
    block_rows: Vec<u32>,
    /// The scalar matrix, compressed sparse columns.
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    symbolic: SymbolicCholesky<u32>,
}

impl BlockPattern {
    /// The pattern of `dim x dim` blocks whose block column `n` holds the
    /// block rows `columns[n]` (sorted, unique, all `>= n`, the first `n`
    /// itself), or `None` when it is too large to index with 32 bits or
    /// its symbolic analysis runs out of memory.
    pub fn new(dim: usize, columns: &[Vec<u32>]) -> Option<Self> {
        let scalars = columns.len() * dim;
        let nnz: usize = columns.iter().map(|c| c.len() * dim * dim).sum();
        if u32::try_from(nnz).is_err() || u32::try_from(scalars).is_err() {
            return None;
        }
        let mut block_offsets = Vec::with_capacity(columns.len() + 1);
        block_offsets.push(0);
        let mut col_ptr = Vec::with_capacity(scalars + 1);
        col_ptr.push(0u32);
        let mut row_idx = Vec::with_capacity(nnz);
        for rows in columns {
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
            block_offsets,
            block_rows: columns.concat(),
            col_ptr,
            row_idx,
            symbolic,
        })
    }

    /// The block size.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Scalar rows (and columns) of the matrix.
    pub fn size(&self) -> usize {
        self.symbolic.nrows()
    }

    /// Writes the matrix's values in this pattern's order into `values`,
    /// block column by block column in parallel: `column(n, out)` adds
    /// column `n`'s entries to `out`, which starts at zero.
    pub fn assemble(
        &self,
        values: &mut Vec<Real>,
        column: impl Fn(usize, &mut BlockColumn<'_>) + Sync,
    ) {
        let dim = self.dim;
        values.resize(self.row_idx.len(), 0.0);
        let mut columns = Vec::with_capacity(self.block_offsets.len() - 1);
        let mut rest = values.as_mut_slice();
        for (n, w) in self.block_offsets.windows(2).enumerate() {
            let (head, tail) = rest.split_at_mut((w[1] - w[0]) * dim * dim);
            columns.push(BlockColumn {
                dim,
                rows: &self.block_rows[w[0]..w[1]],
                values: head,
                n,
            });
            rest = tail;
        }
        columns.into_par_iter().for_each(|mut out| {
            out.values.fill(0.0);
            column(out.n, &mut out);
        });
    }

    /// `y = A x` from the stored lower triangle, to check an assembly.
    #[cfg(test)]
    pub(crate) fn product(&self, values: &[Real], x: &[Real]) -> Vec<Real> {
        let mut y = vec![0.0; x.len()];
        for col in 0..x.len() {
            let range = self.col_ptr[col] as usize..self.col_ptr[col + 1] as usize;
            for (&row, &v) in self.row_idx[range.clone()].iter().zip(&values[range]) {
                let row = row as usize;
                if row > col {
                    y[row] += v * x[col];
                    y[col] += v * x[row];
                } else if row == col {
                    y[row] += v * x[col];
                }
            }
        }
        y
    }
}

/// One block column's values, being assembled.
#[derive(Debug)]
pub struct BlockColumn<'a> {
    dim: usize,
    /// Its block rows, sorted; the first is the diagonal block.
    rows: &'a [u32],
    values: &'a mut [Real],
    n: usize,
}

impl BlockColumn<'_> {
    /// The place of block row `m` among this column's rows, or `None`
    /// when the pattern has no such block (above the diagonal, say).
    pub fn slot(&self, m: u32) -> Option<usize> {
        self.rows.binary_search(&m).ok()
    }

    /// Adds `v` to entry `(b, a)` of the block in row `slot`: row `b` of
    /// that block row, column `a` of this block column.
    pub fn add(&mut self, slot: usize, a: usize, b: usize, v: Real) {
        self.values[(a * self.rows.len() + slot) * self.dim + b] += v;
    }

    /// Subtracts `v` from that entry.
    pub fn sub(&mut self, slot: usize, a: usize, b: usize, v: Real) {
        self.values[(a * self.rows.len() + slot) * self.dim + b] -= v;
    }
}

/// A matrix's values over a [`BlockPattern`], its Cholesky factor and the
/// right-hand side, kept between factorisations so that the arrays are
/// not reallocated.
#[derive(Debug, Clone, Default)]
pub struct SparseCholesky {
    /// The matrix's values in the pattern's order.
    values: Vec<Real>,
    /// The Cholesky factor's values.
    factor: Vec<Real>,
    /// Right-hand side, overwritten by the solution.
    rhs: Vec<Real>,
}

impl SparseCholesky {
    /// Bytes held by the last Cholesky factor.
    pub fn factor_bytes(&self) -> usize {
        self.factor.len() * std::mem::size_of::<Real>()
    }

    /// Assembles the matrix over `pattern` by `column` (as
    /// [`BlockPattern::assemble`]), factorises it as `L L^T` and solves
    /// `A y = b` for `b` from `rhs`; returns `y`, or `None` when the
    /// matrix is not positive definite or memory for the factor cannot be
    /// had.
    pub fn solve(
        &mut self,
        pattern: &BlockPattern,
        column: impl Fn(usize, &mut BlockColumn<'_>) + Sync,
        rhs: impl IntoIterator<Item = Real>,
    ) -> Option<&[Real]> {
        let symbolic = &pattern.symbolic;
        // The two large arrays: their allocation failing is no solve.
        let grow =
            |v: &mut Vec<Real>, len: usize| v.try_reserve(len.saturating_sub(v.len())).is_ok();
        if !grow(&mut self.values, pattern.row_idx.len())
            || !grow(&mut self.factor, symbolic.len_val())
        {
            return None;
        }
        pattern.assemble(&mut self.values, column);
        let par = faer::get_global_parallelism();
        let mut memory = MemBuffer::try_new(
            symbolic
                .factorize_numeric_llt_scratch::<Real>(par, Default::default())
                .or(symbolic.solve_in_place_scratch::<Real>(1, par)),
        )
        .ok()?;
        self.factor.resize(symbolic.len_val(), 0.0);
        let n = symbolic.nrows();
        let matrix = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx),
            &self.values,
        );
        let llt = symbolic
            .factorize_numeric_llt(
                &mut self.factor,
                matrix,
                Side::Lower,
                LltRegularization::default(),
                par,
                MemStack::new(&mut memory),
                Default::default(),
            )
            .ok()?;
        self.rhs.clear();
        self.rhs.extend(rhs);
        llt.solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut self.rhs, n, 1),
            par,
            MemStack::new(&mut memory),
        );
        Some(&self.rhs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain of `count` blocks, each coupled to the next: diagonal
    /// blocks `8 - a` on the diagonal and 1 off it (at least 4 by
    /// Gershgorin), `-I` beside them (at most 2), so positive definite.
    fn chain(
        dim: usize,
        count: u32,
    ) -> (BlockPattern, impl Fn(usize, &mut BlockColumn<'_>) + Sync) {
        let columns: Vec<Vec<u32>> = (0..count)
            .map(|n| (n..(n + 2).min(count)).collect())
            .collect();
        let pattern = BlockPattern::new(dim, &columns).expect("pattern");
        let column = move |_: usize, out: &mut BlockColumn<'_>| {
            for a in 0..dim {
                for b in 0..dim {
                    let v = if a == b { 8.0 - a as Real } else { 1.0 };
                    out.add(0, a, b, v);
                }
                if out.rows.len() > 1 {
                    out.sub(1, a, a, 1.0);
                }
            }
        };
        (pattern, column)
    }

    #[test]
    fn a_block_chain_factors_and_solves_to_rounding() {
        for dim in [1, 2, 3] {
            let (pattern, column) = chain(dim, 9);
            let n = pattern.size();
            assert_eq!(n, 9 * dim);
            let b: Vec<Real> = (0..n).map(|k| (k as Real * 0.7).sin()).collect();
            let mut solver = SparseCholesky::default();
            let y = solver
                .solve(&pattern, &column, b.iter().copied())
                .expect("positive definite")
                .to_vec();
            let mut values = Vec::new();
            pattern.assemble(&mut values, &column);
            let ay = pattern.product(&values, &y);
            let residual = ay
                .iter()
                .zip(&b)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<Real>()
                .sqrt();
            let scale = b.iter().map(|b| b * b).sum::<Real>().sqrt();
            let limit = 8.0 * Real::EPSILON * n as Real * scale;
            assert!(residual <= limit, "{dim}D: {residual:e} > {limit:e}");
            assert!(solver.factor_bytes() > 0);
        }
    }

    #[test]
    fn an_indefinite_matrix_does_not_factor() {
        let pattern = BlockPattern::new(1, &[vec![0, 1], vec![1]]).expect("pattern");
        // [[1, 2], [2, 1]]: eigenvalues 3 and -1.
        let column = |n: usize, out: &mut BlockColumn<'_>| {
            out.add(0, 0, 0, 1.0);
            if n == 0 {
                out.add(1, 0, 0, 2.0);
            }
        };
        let mut solver = SparseCholesky::default();
        assert!(solver.solve(&pattern, column, [1.0, 1.0]).is_none());
    }
}
