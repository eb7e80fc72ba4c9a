//! The residuals of a least-squares problem and their Jacobian by blocks:
//! each block stores its stencil once (column bases and weights) and its
//! rows as derivatives by the block's features, and gathers and scatters
//! through the stencil for the products (see the parent module).

use super::super::progress::Energies;
use crate::math::Real;
use std::ops::Range;

/// Which energy a residual belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Term {
    Handle,
    Rigidity,
    Volume,
    Velocity,
    Acceleration,
    Obstacle,
}

impl Term {
    fn slot(self, e: &mut Energies) -> &mut Real {
        match self {
            Self::Handle => &mut e.handle,
            Self::Rigidity => &mut e.rigidity,
            Self::Volume => &mut e.volume,
            Self::Velocity => &mut e.velocity,
            Self::Acceleration => &mut e.acceleration,
            Self::Obstacle => &mut e.obstacle,
        }
    }
}

/// Features per block at most: a 3x3 gradient.
pub(super) const MAX_FEATURES: usize = 9;

/// Where a block's rows, stencil and matrix start.
#[derive(Debug, Clone, Copy)]
pub(super) struct Block {
    pub(super) row: u32,
    stencil: u32,
    /// Weights are `q` per stencil entry, so their start differs.
    weight: u32,
    matrix: u32,
    /// Unknowns per stencil entry (the dimension).
    pub(super) dim: u8,
    /// Weights per stencil entry.
    q: u8,
}

impl Block {
    /// Features of the block: `dim * q`.
    pub(super) fn features(&self) -> usize {
        usize::from(self.dim) * usize::from(self.q)
    }
}

/// Residuals and, when asked for, their Jacobian by blocks.
#[derive(Debug, Clone, Default)]
pub(crate) struct Rows {
    pub residuals: Vec<Real>,
    pub terms: Vec<Term>,
    pub(super) blocks: Vec<Block>,
    /// Each stencil entry's first unknown `b_j`.
    pub(super) bases: Vec<u32>,
    weights: Vec<Real>,
    /// Each block's rows' derivatives by its features, row-major.
    matrix: Vec<Real>,
    jacobian: bool,
}

impl Rows {
    pub(crate) fn reset(&mut self, jacobian: bool) {
        self.residuals.clear();
        self.terms.clear();
        self.blocks.clear();
        self.bases.clear();
        self.weights.clear();
        self.matrix.clear();
        self.jacobian = jacobian;
    }

    /// Starts a block: the rows pushed next depend on the unknowns
    /// through features `z_(a, c) = sum_j w_(j, c) x_(b_j + a)`, `a <
    /// dim`, `c < q`, over the `stencil` entries `(b_j, w_j)` (the first
    /// `q` weights of each are used). `q` is 1 (a field value) or `dim`
    /// (a gradient).
    pub fn block(
        &mut self,
        dim: usize,
        q: usize,
        stencil: impl IntoIterator<Item = (usize, [Real; 3])>,
    ) {
        // An internal invariant, not input: the products are specialised
        // for these shapes.
        assert!(
            (1..=3).contains(&dim) && (q == 1 || q == dim),
            "a block has dim 1 to 3 and one or dim weights per entry"
        );
        if !self.jacobian {
            return;
        }
        self.blocks.push(Block {
            row: self.residuals.len() as u32,
            stencil: self.bases.len() as u32,
            weight: self.weights.len() as u32,
            matrix: self.matrix.len() as u32,
            dim: dim as u8,
            q: q as u8,
        });
        for (base, w) in stencil {
            self.bases.push(base as u32);
            self.weights.extend_from_slice(&w[..q]);
        }
    }

    /// Appends a residual of the current block and its derivative by the
    /// block's features, feature `(a, c)` at `a * q + c`.
    pub fn push(&mut self, term: Term, residual: Real, derivative: &[Real]) {
        self.residuals.push(residual);
        self.terms.push(term);
        if self.jacobian {
            debug_assert_eq!(
                Some(derivative.len()),
                self.blocks.last().map(Block::features)
            );
            self.matrix.extend_from_slice(derivative);
        }
    }

    /// Appends `other`'s rows and blocks after these.
    pub(super) fn append(&mut self, other: &Rows) {
        let (row, stencil, weight, matrix) = (
            self.residuals.len() as u32,
            self.bases.len() as u32,
            self.weights.len() as u32,
            self.matrix.len() as u32,
        );
        self.residuals.extend_from_slice(&other.residuals);
        self.terms.extend_from_slice(&other.terms);
        self.blocks.extend(other.blocks.iter().map(|b| Block {
            row: b.row + row,
            stencil: b.stencil + stencil,
            weight: b.weight + weight,
            matrix: b.matrix + matrix,
            ..*b
        }));
        self.bases.extend_from_slice(&other.bases);
        self.weights.extend_from_slice(&other.weights);
        self.matrix.extend_from_slice(&other.matrix);
    }

    /// Each term's sum of squared residuals.
    pub(super) fn energies(&self) -> Energies {
        let mut e = Energies::default();
        for (r, t) in self.residuals.iter().zip(&self.terms) {
            *t.slot(&mut e) += r * r;
        }
        e
    }

    /// Block `b`'s rows and stencil entries.
    pub(super) fn ranges(&self, b: usize) -> (Range<usize>, Range<usize>) {
        let this = &self.blocks[b];
        let (row_end, stencil_end) = match self.blocks.get(b + 1) {
            Some(next) => (next.row as usize, next.stencil as usize),
            None => (self.residuals.len(), self.bases.len()),
        };
        (
            this.row as usize..row_end,
            this.stencil as usize..stencil_end,
        )
    }

    /// The weights of stencil entry `s` of block `b`.
    pub(super) fn weights_of(&self, b: usize, s: usize) -> &[Real] {
        let block = &self.blocks[b];
        let q = usize::from(block.q);
        let start = block.weight as usize + (s - block.stencil as usize) * q;
        &self.weights[start..start + q]
    }

    /// Starts a block of the field's value at a point, `sum_j c_j
    /// x_(b_j + .)`, over `(b_j, c_j)`: a handle, keyframe, velocity,
    /// acceleration or obstacle.
    pub fn value_block(&mut self, dim: usize, entries: &[(usize, Real)]) {
        self.block(dim, 1, entries.iter().map(|&(b, c)| (b, [c, 0.0, 0.0])));
    }

    /// Block `b`'s features of `v`.
    pub(super) fn gather(
        &self,
        b: usize,
        stencil: Range<usize>,
        v: &[Real],
    ) -> [Real; MAX_FEATURES] {
        match (self.blocks[b].dim, self.blocks[b].q) {
            (3, 3) => self.gather_fixed::<3, 3>(b, stencil, v),
            (3, 1) => self.gather_fixed::<3, 1>(b, stencil, v),
            (2, 2) => self.gather_fixed::<2, 2>(b, stencil, v),
            (2, 1) => self.gather_fixed::<2, 1>(b, stencil, v),
            _ => self.gather_fixed::<1, 1>(b, stencil, v),
        }
    }

    /// [`Self::gather`] with the block's shape known to the compiler,
    /// which unrolls the inner loops: the products spend their time here.
    fn gather_fixed<const D: usize, const Q: usize>(
        &self,
        b: usize,
        stencil: Range<usize>,
        v: &[Real],
    ) -> [Real; MAX_FEATURES] {
        let start = self.blocks[b].weight as usize;
        let bases = &self.bases[stencil];
        let weights = &self.weights[start..start + bases.len() * Q];
        let mut z = [0.0; MAX_FEATURES];
        for (&base, w) in bases.iter().zip(weights.chunks_exact(Q)) {
            let x = &v[base as usize..base as usize + D];
            for a in 0..D {
                for c in 0..Q {
                    z[a * Q + c] += w[c] * x[a];
                }
            }
        }
        z
    }

    /// `out[b_j + a] += sum_c w_(j, c) y_(a, c)` over block `b`'s stencil.
    pub(super) fn scatter(&self, b: usize, stencil: Range<usize>, y: &[Real], out: &mut [Real]) {
        match (self.blocks[b].dim, self.blocks[b].q) {
            (3, 3) => self.scatter_fixed::<3, 3>(b, stencil, y, out),
            (3, 1) => self.scatter_fixed::<3, 1>(b, stencil, y, out),
            (2, 2) => self.scatter_fixed::<2, 2>(b, stencil, y, out),
            (2, 1) => self.scatter_fixed::<2, 1>(b, stencil, y, out),
            _ => self.scatter_fixed::<1, 1>(b, stencil, y, out),
        }
    }

    fn scatter_fixed<const D: usize, const Q: usize>(
        &self,
        b: usize,
        stencil: Range<usize>,
        y: &[Real],
        out: &mut [Real],
    ) {
        let start = self.blocks[b].weight as usize;
        let bases = &self.bases[stencil];
        let weights = &self.weights[start..start + bases.len() * Q];
        let y = &y[..D * Q];
        for (&base, w) in bases.iter().zip(weights.chunks_exact(Q)) {
            let out = &mut out[base as usize..base as usize + D];
            for a in 0..D {
                let mut sum = 0.0;
                for c in 0..Q {
                    sum += w[c] * y[a * Q + c];
                }
                out[a] += sum;
            }
        }
    }

    /// Block `b`'s matrix, `rows x features`.
    pub(super) fn matrix_of(&self, b: usize, rows: usize) -> &[Real] {
        let block = &self.blocks[b];
        let start = block.matrix as usize;
        &self.matrix[start..start + rows * block.features()]
    }

    /// `d r_k / d x_c`, for tests.
    #[cfg(test)]
    pub(crate) fn derivative(&self, k: usize, c: usize) -> Real {
        let b = self.blocks.partition_point(|b| b.row as usize <= k) - 1;
        let (rows, stencil) = self.ranges(b);
        let block = self.blocks[b];
        let dim = usize::from(block.dim);
        let row = &self.matrix_of(b, rows.len())[(k - rows.start) * block.features()..];
        stencil
            .filter(|&s| (self.bases[s] as usize..self.bases[s] as usize + dim).contains(&c))
            .map(|s| column_entry(row, c - self.bases[s] as usize, self.weights_of(b, s)))
            .sum()
    }
}

/// The entry of a block's Jacobian in `row` (its derivative by the
/// features) and the column of component `a` of a stencil entry with
/// weights `w`: `sum_c row_(a, c) w_c`.
pub(super) fn column_entry(row: &[Real], a: usize, w: &[Real]) -> Real {
    let q = w.len();
    row[a * q..(a + 1) * q]
        .iter()
        .zip(w)
        .map(|(r, w)| r * w)
        .sum()
}
