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
//! matrix with that sparsity. A `Factor` keeps one numeric
//! factorisation for many solves, its two triangular halves apart (the
//! modal eigensolver, `eigen.rs`, needs each on its own).

use crate::math::Real;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::linalg::{temp_mat_scratch, temp_mat_zeroed};
use faer::mat::AsMatMut;
use faer::perm::permute_rows;
use faer::prelude::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_lower_triangular_transpose_in_place,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, MatRef, Par, Side};
use rayon::prelude::*;

/// Stored values above which [`BlockPattern::product_pair`] splits its
/// columns over two threads. Measured with `cargo bench -p
/// meshless-engine --bench shell`, two runs each way: a linear shell's step
/// on the cap (93,294 values) took 0.63 ms split against 0.45 ms whole
/// (waking a thread costs more than half of a 0.1 ms product), on the
/// closed sphere (232,569) 1.0 ms split against 1.3 ms whole.
pub(crate) const PAIR_SPLIT_VALUES: usize = 1 << 17;

/// The sparsity of a symmetric block matrix and its symbolic
/// factorisation.
#[derive(Debug, Clone)]
pub struct BlockPattern {
    dim: usize,
    /// Block rows `m >= n` of each block column `n`, sorted.
    block_offsets: Vec<usize>,
    block_rows: Vec<u32>,
    /// The scalar matrix, compressed sparse columns.
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    /// Shared by clones: the analysis never changes once made.
    symbolic: std::sync::Arc<SymbolicCholesky<u32>>,
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
            symbolic: std::sync::Arc::new(symbolic),
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

    /// Scalar values a matrix over this pattern has (the length of the
    /// `values` that [`Self::assemble`] fills).
    pub(crate) fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// The place of each scalar diagonal entry `A_ii` in the values, in
    /// order of `i`: every scalar column starts with its diagonal block,
    /// so `A_ii` is entry `i mod dim` of column `i`. For traces, diagonal
    /// checks and adding a diagonal matrix without assembling.
    pub(crate) fn diagonal(&self) -> impl Iterator<Item = usize> + '_ {
        let dim = self.dim;
        self.col_ptr[..self.size()]
            .iter()
            .enumerate()
            .map(move |(i, &start)| start as usize + i % dim)
    }

    /// `y = A x`, column by column, from the stored lower triangle. One
    /// thread: each stored entry adds to two rows of `y`, which a
    /// parallel loop over columns could not do without locks, and the
    /// product is cheap beside the factorisations and solves it sits
    /// between.
    pub(crate) fn multiply(&self, values: &[Real], x: MatRef<'_, Real>, mut y: MatMut<'_, Real>) {
        // Strided columns are copied into contiguous ones (every caller
        // passes contiguous ones today).
        let (mut x_copy, mut y_copy) = (Vec::new(), Vec::new());
        for j in 0..x.ncols() {
            let column = x.col(j);
            let x = match column.try_as_col_major() {
                Some(x) => x.as_slice(),
                None => {
                    x_copy.clear();
                    x_copy.extend(column.iter().copied());
                    &x_copy
                }
            };
            let mut target = y.rb_mut().col_mut(j);
            match target.rb_mut().try_as_col_major_mut() {
                Some(y) => {
                    let y = y.as_slice_mut();
                    y.fill(0.0);
                    self.multiply_into([values], [x], [y], 0..x.len());
                }
                None => {
                    y_copy.clear();
                    y_copy.resize(x.len(), 0.0);
                    self.multiply_into([values], [x], [&mut y_copy], 0..x.len());
                    for (t, v) in target.iter_mut().zip(&y_copy) {
                        *t = *v;
                    }
                }
            }
        }
    }

    /// Adds `A_m x_m` to `y_m` for each of `M` matrices over this
    /// pattern, over the scalar `columns`: one pass reads the indices once
    /// for all of them, and each product's sums run in the same order
    /// whatever `M` is. Each scalar column starts with its diagonal block
    /// (see the module's comment): its entries above the diagonal are
    /// skipped, the one on it read once, and every later entry lies below
    /// it, so the long inner loop has no test per entry.
    fn multiply_into<const M: usize>(
        &self,
        values: [&[Real]; M],
        x: [&[Real]; M],
        y: [&mut [Real]; M],
        columns: std::ops::Range<usize>,
    ) {
        let dim = self.dim;
        for col in columns {
            let (start, end) = (self.col_ptr[col] as usize, self.col_ptr[col + 1] as usize);
            let a = col % dim;
            let xc: [Real; M] = std::array::from_fn(|m| x[m][col]);
            let mut sum: [Real; M] = std::array::from_fn(|m| values[m][start + a] * xc[m]);
            for b in a + 1..dim {
                let row = col - a + b;
                for m in 0..M {
                    let v = values[m][start + b];
                    y[m][row] += v * xc[m];
                    sum[m] += v * x[m][row];
                }
            }
            let rows = &self.row_idx[start + dim..end];
            let below: [&[Real]; M] = std::array::from_fn(|m| &values[m][start + dim..end]);
            for (k, &row) in rows.iter().enumerate() {
                let row = row as usize;
                for m in 0..M {
                    let v = below[m][k];
                    y[m][row] += v * xc[m];
                    sum[m] += v * x[m][row];
                }
            }
            for m in 0..M {
                y[m][col] += sum[m];
            }
        }
    }

    /// `(A x, B z)` for two matrices over this pattern (`a` and `b` their
    /// values) in one pass over it: a linear shell's step reads its
    /// constant `K` and `M` together, each index once.
    ///
    /// Below [`PAIR_SPLIT_VALUES`] values each product's sums are
    /// [`Self::product`]'s in the same order (the same kernel: bit for bit
    /// the one matrix's product). Above it the columns are cut into two halves of
    /// equal work, summed on two threads into vectors of their own and
    /// added: the same cut on any number of threads, so the same result.
    pub(crate) fn product_pair(
        &self,
        a: &[Real],
        x: &[Real],
        b: &[Real],
        z: &[Real],
    ) -> (Vec<Real>, Vec<Real>) {
        let n = x.len();
        let part = |columns: std::ops::Range<usize>| {
            let (mut ya, mut yb) = (vec![0.0; n], vec![0.0; n]);
            self.multiply_into([a, b], [x, z], [&mut ya, &mut yb], columns);
            (ya, yb)
        };
        let total = self.col_ptr.last().map_or(0, |&v| v as usize);
        if total < PAIR_SPLIT_VALUES {
            return part(0..n);
        }
        let middle = self
            .col_ptr
            .partition_point(|&p| (p as usize) < total / 2)
            .min(n);
        let ((mut ya, mut yb), (ya2, yb2)) = rayon::join(|| part(0..middle), || part(middle..n));
        for (y, y2) in ya.iter_mut().zip(&ya2).chain(yb.iter_mut().zip(&yb2)) {
            *y += y2;
        }
        (ya, yb)
    }

    /// `y = A x` from the stored lower triangle: to check an assembly, and
    /// a linear shell's forces from its constant stiffness.
    pub(crate) fn product(&self, values: &[Real], x: &[Real]) -> Vec<Real> {
        let mut y = vec![0.0; x.len()];
        self.multiply(
            values,
            MatRef::from_column_major_slice(x, x.len(), 1),
            MatMut::from_column_major_slice_mut(&mut y, x.len(), 1),
        );
        y
    }

    /// Writes into `factor` the Cholesky factor of the matrix with
    /// `values` (in this pattern's order), reusing its allocation.
    fn factorize_into(
        &self,
        values: &[Real],
        factor: &mut Vec<Real>,
        par: Par,
    ) -> Result<(), FactorError> {
        let symbolic = &self.symbolic;
        // The factor is the largest array: its allocation failing is an
        // error to report, not an abort.
        factor
            .try_reserve(symbolic.len_val().saturating_sub(factor.len()))
            .map_err(|_| FactorError::OutOfMemory)?;
        factor.resize(symbolic.len_val(), 0.0);
        let mut memory = MemBuffer::try_new(
            symbolic.factorize_numeric_llt_scratch::<Real>(par, Default::default()),
        )
        .map_err(|_| FactorError::OutOfMemory)?;
        let n = self.size();
        let matrix = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx),
            values,
        );
        match symbolic.factorize_numeric_llt(
            factor,
            matrix,
            Side::Lower,
            LltRegularization::default(),
            par,
            MemStack::new(&mut memory),
            Default::default(),
        ) {
            Ok(_) => Ok(()),
            Err(LltError::NonPositivePivot { index }) => {
                // The pivot is numbered in the fill-reducing order.
                let dof = symbolic
                    .perm()
                    .and_then(|p| p.arrays().0.get(index).map(|&i| i as usize))
                    .unwrap_or(index);
                Err(FactorError::NotPositiveDefinite { dof })
            }
        }
    }

    /// The Cholesky factor of the matrix with `values` (in this pattern's
    /// order), kept for many solves.
    ///
    /// # Errors
    /// [`FactorError`] when the matrix is not positive definite or the
    /// factor's memory cannot be had.
    pub(crate) fn factorize(&self, values: &[Real]) -> Result<Factor<'_>, FactorError> {
        let mut factor = Vec::new();
        self.factorize_into(values, &mut factor, faer::get_global_parallelism())?;
        Ok(Factor {
            symbolic: &self.symbolic,
            values: factor,
        })
    }
}

/// Why a matrix did not factorise.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FactorError {
    /// A pivot was not positive: the matrix is not positive definite.
    /// `dof` is the scalar row whose pivot failed, in the caller's
    /// numbering: where the trouble showed, not necessarily its cause.
    NotPositiveDefinite {
        /// The row.
        dof: usize,
    },
    /// Memory for the factor or its scratch could not be had.
    OutOfMemory,
}

/// A Cholesky factorisation `P A P^T = L L^T` over a [`BlockPattern`],
/// kept so that one factorisation serves many solves. `G = P^T L` is a
/// square root of `A` (`A = G G^T`); the solves with `G` and `G^T` are
/// offered apart, since a symmetric transformation such as `G^-1 B G^-T`
/// needs each on its own. Runs with faer's global parallelism.
#[derive(Debug)]
pub(crate) struct Factor<'a> {
    symbolic: &'a SymbolicCholesky<u32>,
    /// `L`'s values.
    values: Vec<Real>,
}

impl Factor<'_> {
    /// Scratch for [`Self::solve_g`] and [`Self::solve_gt`] on `ncols`
    /// columns: a permuted copy and faer's own.
    pub(crate) fn scratch(&self, ncols: usize, par: Par) -> StackReq {
        StackReq::all_of(&[
            temp_mat_scratch::<Real>(self.symbolic.nrows(), ncols),
            self.symbolic.solve_in_place_scratch::<Real>(ncols, par),
        ])
    }

    /// `rhs = G^-1 rhs = L^-1 P rhs`.
    pub(crate) fn solve_g(&self, mut rhs: MatMut<'_, Real>, par: Par, stack: &mut MemStack) {
        let (mut x, stack) = temp_mat_zeroed::<Real, _, _>(rhs.nrows(), rhs.ncols(), stack);
        let mut x = x.as_mat_mut();
        match self.symbolic.perm() {
            Some(perm) => permute_rows(x.rb_mut(), rhs.rb(), perm),
            None => x.copy_from(rhs.rb()),
        }
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(symbolic) => solve_lower_triangular_in_place(
                SparseColMatRef::new(symbolic.factor(), &self.values),
                Conj::No,
                x.rb_mut(),
                par,
            ),
            SymbolicCholeskyRaw::Supernodal(symbolic) => {
                SupernodalLltRef::new(symbolic, &self.values).l_solve_with_conj(
                    Conj::No,
                    x.rb_mut(),
                    par,
                    stack,
                );
            }
        }
        rhs.copy_from(x.rb());
    }

    /// `rhs = G^-T rhs = P^T L^-T rhs`.
    pub(crate) fn solve_gt(&self, mut rhs: MatMut<'_, Real>, par: Par, stack: &mut MemStack) {
        let (mut x, stack) = temp_mat_zeroed::<Real, _, _>(rhs.nrows(), rhs.ncols(), stack);
        let mut x = x.as_mat_mut();
        x.copy_from(rhs.rb());
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(symbolic) => {
                solve_lower_triangular_transpose_in_place(
                    SparseColMatRef::new(symbolic.factor(), &self.values),
                    Conj::No,
                    x.rb_mut(),
                    par,
                );
            }
            SymbolicCholeskyRaw::Supernodal(symbolic) => {
                SupernodalLltRef::new(symbolic, &self.values).l_transpose_solve_with_conj(
                    Conj::No,
                    x.rb_mut(),
                    par,
                    stack,
                );
            }
        }
        match self.symbolic.perm() {
            Some(perm) => permute_rows(rhs.rb_mut(), x.rb(), perm.inverse()),
            None => rhs.copy_from(x.rb()),
        }
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
        self.solve_with(pattern, column, |_| {}, rhs)
    }

    /// [`Self::solve`], with `finish` given the assembled values (in the
    /// pattern's order) before the factorisation: to add matrices held
    /// assembled over the same pattern (a mass, a penalty).
    pub fn solve_with(
        &mut self,
        pattern: &BlockPattern,
        column: impl Fn(usize, &mut BlockColumn<'_>) + Sync,
        finish: impl FnOnce(&mut [Real]),
        rhs: impl IntoIterator<Item = Real>,
    ) -> Option<&[Real]> {
        // The values' allocation failing is no solve (the factor's too,
        // in `factorize_into`).
        if self
            .values
            .try_reserve(pattern.nnz().saturating_sub(self.values.len()))
            .is_err()
        {
            return None;
        }
        pattern.assemble(&mut self.values, column);
        finish(&mut self.values);
        let par = faer::get_global_parallelism();
        pattern
            .factorize_into(&self.values, &mut self.factor, par)
            .ok()?;
        self.solve_factored(pattern, rhs)
    }

    /// Factorises the matrix with `values` (in `pattern`'s order) and keeps
    /// the factor for [`Self::solve_factored`]: for a matrix that stays
    /// the same over many solves. `false` when it is not positive definite
    /// or the factor's memory cannot be had.
    pub fn factorize(&mut self, pattern: &BlockPattern, values: &[Real]) -> bool {
        let par = faer::get_global_parallelism();
        pattern
            .factorize_into(values, &mut self.factor, par)
            .is_ok()
    }

    /// Solves `A y = b` for `b` from `rhs` with the factor the last
    /// [`Self::factorize`] (or solve) left, over the same `pattern`;
    /// returns `y`, or `None` when scratch memory cannot be had.
    pub fn solve_factored(
        &mut self,
        pattern: &BlockPattern,
        rhs: impl IntoIterator<Item = Real>,
    ) -> Option<&[Real]> {
        let symbolic = &pattern.symbolic;
        if self.factor.len() != symbolic.len_val() {
            return None;
        }
        let par = faer::get_global_parallelism();
        let mut memory =
            MemBuffer::try_new(symbolic.solve_in_place_scratch::<Real>(1, par)).ok()?;
        let n = symbolic.nrows();
        let llt = LltRef::new(symbolic, &self.factor);
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

    /// Above the split, the paired product is each product to rounding.
    #[test]
    fn a_split_paired_product_is_each_product_to_rounding() {
        let (pattern, column) = chain(3, 9000);
        let mut a = Vec::new();
        pattern.assemble(&mut a, &column);
        assert!(a.len() > PAIR_SPLIT_VALUES, "{} values", a.len());
        let b: Vec<Real> = a.iter().map(|v| 0.5 * v - 0.125).collect();
        let n = pattern.size();
        let x: Vec<Real> = (0..n).map(|k| (k as Real * 0.9).cos()).collect();
        let z: Vec<Real> = (0..n).map(|k| (k as Real * 0.4).sin()).collect();
        let (ax, bz) = pattern.product_pair(&a, &x, &b, &z);
        for (pair, one) in [(ax, pattern.product(&a, &x)), (bz, pattern.product(&b, &z))] {
            let worst = pair
                .iter()
                .zip(&one)
                .map(|(p, o)| (p - o).abs())
                .fold(0.0, Real::max);
            assert!(worst < 1e-13, "{worst:e}");
        }
    }

    /// Below the split, the paired product is each matrix's own product,
    /// bit for bit, and the product is the dense matrix's (both triangles
    /// from the stored lower one).
    #[test]
    fn a_paired_product_is_each_product() {
        for dim in [1, 2, 3] {
            let (pattern, column) = chain(dim, 7);
            let n = pattern.size();
            let mut a = Vec::new();
            pattern.assemble(&mut a, &column);
            let b: Vec<Real> = a.iter().map(|v| 0.5 * v + 0.25).collect();
            let x: Vec<Real> = (0..n).map(|k| (k as Real * 0.9).cos()).collect();
            let z: Vec<Real> = (0..n).map(|k| (k as Real * 0.4).sin()).collect();
            let (ax, bz) = pattern.product_pair(&a, &x, &b, &z);
            assert_eq!(ax, pattern.product(&a, &x), "{dim}D");
            assert_eq!(bz, pattern.product(&b, &z), "{dim}D");
            // The dense matrix from unit vectors' products is symmetric
            // and reproduces the product.
            let dense: Vec<Vec<Real>> = (0..n)
                .map(|j| {
                    let e: Vec<Real> = (0..n).map(|i| Real::from(u8::from(i == j))).collect();
                    pattern.product(&a, &e)
                })
                .collect();
            for (i, column) in dense.iter().enumerate() {
                for (j, other) in dense.iter().enumerate() {
                    assert_eq!(column[j], other[i], "{dim}D ({i}, {j})");
                }
                let row: Real = dense.iter().zip(&x).map(|(c, xj)| c[i] * xj).sum();
                assert!((row - ax[i]).abs() < 1e-12, "{dim}D row {i}");
            }
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
