//! The products of the Jacobian by blocks: `J v`, `J^T w` and
//! `diag(J^T J)`, split over rayon's threads in runs of blocks of about
//! equal work.
//!
//! `J v` writes each run's own rows; `J^T w` and the diagonal scatter
//! into one scratch vector per run, summed in run order afterwards, so
//! they depend on the thread count (which sets the runs) but not on
//! rayon's scheduling.

use super::rows::{MAX_FEATURES, Rows, column_entry};
use crate::math::Real;
use rayon::prelude::*;

/// The Jacobian's blocks split into one contiguous run per thread, with a
/// scratch vector each for the scattered products.
#[derive(Debug, Default)]
pub(super) struct Products {
    /// Block boundaries of the runs.
    runs: Vec<usize>,
    scratch: Vec<Vec<Real>>,
}

impl Products {
    /// Splits `j`'s blocks into runs of about equal work.
    pub(super) fn split(&mut self, j: &Rows, n: usize) {
        let parts = rayon::current_num_threads().max(1);
        let work = |b: usize| {
            let (rows, stencil) = j.ranges(b);
            rows.len() * j.blocks[b].features() + stencil.len() * j.blocks[b].features()
        };
        let total: usize = (0..j.blocks.len()).map(work).sum();
        self.runs.clear();
        self.runs.push(0);
        let mut done = 0;
        for b in 0..j.blocks.len() {
            done += work(b);
            if done * parts >= total * self.runs.len() && self.runs.len() < parts {
                self.runs.push(b + 1);
            }
        }
        if *self.runs.last().unwrap_or(&0) != j.blocks.len() {
            self.runs.push(j.blocks.len());
        }
        self.scratch.resize_with(self.runs.len() - 1, Vec::new);
        for s in &mut self.scratch {
            s.clear();
            s.resize(n, 0.0);
        }
    }

    /// `out = J v`; each run writes its own rows.
    pub(super) fn apply_j(&self, j: &Rows, v: &[Real], out: &mut [Real]) {
        let mut slices = Vec::with_capacity(self.runs.len());
        let mut rest = &mut out[..];
        let mut at = 0;
        for w in self.runs.windows(2) {
            let end = j
                .blocks
                .get(w[1])
                .map_or(j.residuals.len(), |b| b.row as usize);
            let (head, tail) = rest.split_at_mut(end - at);
            slices.push((w[0]..w[1], at, head));
            rest = tail;
            at = end;
        }
        slices.into_par_iter().for_each(|(blocks, first, out)| {
            for b in blocks {
                let (rows, stencil) = j.ranges(b);
                let z = j.gather(b, stencil, v);
                let p = j.blocks[b].features();
                let m = j.matrix_of(b, rows.len());
                for (k, row) in rows.clone().zip(m.chunks_exact(p)) {
                    out[k - first] = row.iter().zip(&z).map(|(a, z)| a * z).sum();
                }
            }
        });
    }

    /// `out = J^T w`, run by run into the scratch vectors, then summed.
    pub(super) fn apply_jt(&mut self, j: &Rows, w: &[Real], out: &mut [Real]) {
        self.scratch
            .par_iter_mut()
            .zip(self.runs.par_windows(2))
            .for_each(|(scratch, run)| {
                scratch.fill(0.0);
                for b in run[0]..run[1] {
                    let (rows, stencil) = j.ranges(b);
                    let p = j.blocks[b].features();
                    let m = j.matrix_of(b, rows.len());
                    // y = A^T w over the block's rows, then scattered.
                    let mut y = [0.0; MAX_FEATURES];
                    for (row, w) in m.chunks_exact(p).zip(&w[rows]) {
                        for (y, a) in y.iter_mut().zip(row) {
                            *y += a * w;
                        }
                    }
                    j.scatter(b, stencil, &y, scratch);
                }
            });
        self.sum_into(out);
    }

    fn sum_into(&self, out: &mut [Real]) {
        out.fill(0.0);
        for s in &self.scratch {
            for (o, v) in out.iter_mut().zip(s) {
                *o += v;
            }
        }
    }

    /// `out = diag(J^T J)`: per stencil entry and component, the squared
    /// norm of its Jacobian column within the block.
    pub(super) fn diagonal(&mut self, j: &Rows, out: &mut [Real]) {
        self.scratch
            .par_iter_mut()
            .zip(self.runs.par_windows(2))
            .for_each(|(scratch, run)| {
                scratch.fill(0.0);
                for b in run[0]..run[1] {
                    let (rows, stencil) = j.ranges(b);
                    let block = j.blocks[b];
                    let (dim, p) = (usize::from(block.dim), block.features());
                    let m = j.matrix_of(b, rows.len());
                    for s in stencil {
                        let base = j.bases[s] as usize;
                        let w = j.weights_of(b, s);
                        for a in 0..dim {
                            scratch[base + a] += m
                                .chunks_exact(p)
                                .map(|row| column_entry(row, a, w).powi(2))
                                .sum::<Real>();
                        }
                    }
                }
            });
        self.sum_into(out);
    }
}

#[cfg(test)]
mod tests {
    use super::super::rows::Term;
    use super::super::{LeastSquares, evaluate};
    use super::*;
    use crate::linalg::{Sequential, Space};

    /// Blocks of both kinds, overlapping stencils: the products and the
    /// diagonal by blocks against the Jacobian entry by entry.
    #[test]
    fn block_products_match_the_jacobian() {
        struct Mixed;
        impl LeastSquares for Mixed {
            fn unknowns(&self) -> usize {
                3 * 7
            }
            fn groups(&self) -> usize {
                40
            }
            fn group(&self, g: usize, _: &[Real], rows: &mut Rows) {
                let value = |k: usize| ((g * 31 + k * 17) % 13) as Real / 6.0 - 1.0;
                let stencil = (0..3).map(|j| {
                    let particle = (g + 2 * j) % 7;
                    (particle * 3, [value(j), value(j + 3), value(j + 6)])
                });
                let (q, rows_here) = if g.is_multiple_of(2) { (3, 5) } else { (1, 2) };
                rows.block(3, q, stencil);
                for r in 0..rows_here {
                    let derivative: Vec<Real> = (0..3 * q).map(|f| value(10 + r * 9 + f)).collect();
                    rows.push(Term::Rigidity, value(r), &derivative);
                }
            }
        }
        let n = Mixed.unknowns();
        let mut rows = Rows::default();
        evaluate(&Mixed, &vec![0.0; n], true, &mut rows);
        let m = rows.residuals.len();
        let dense: Vec<Vec<Real>> = (0..m)
            .map(|k| (0..n).map(|c| rows.derivative(k, c)).collect())
            .collect();
        let v: Vec<Real> = (0..n).map(|c| (c as Real * 0.37).sin()).collect();
        let w: Vec<Real> = (0..m).map(|k| (k as Real * 0.53).cos()).collect();
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            pool.install(|| {
                let mut products = Products::default();
                products.split(&rows, n);
                let mut jv = vec![0.0; m];
                products.apply_j(&rows, &v, &mut jv);
                let mut jtw = vec![0.0; n];
                products.apply_jt(&rows, &w, &mut jtw);
                let mut diag = vec![0.0; n];
                products.diagonal(&rows, &mut diag);
                for k in 0..m {
                    let expected = Sequential::dot(&dense[k], &v);
                    assert!((jv[k] - expected).abs() < 1e-12, "J v, row {k}");
                }
                for c in 0..n {
                    let expected: Real = (0..m).map(|k| dense[k][c] * w[k]).sum();
                    assert!((jtw[c] - expected).abs() < 1e-12, "J^T w, column {c}");
                    let expected: Real = (0..m).map(|k| dense[k][c] * dense[k][c]).sum();
                    assert!((diag[c] - expected).abs() < 1e-12, "diagonal, column {c}");
                }
            });
        }
    }
}
