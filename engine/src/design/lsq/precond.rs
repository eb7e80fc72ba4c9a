//! The optimiser's preconditioner: the blocks of the normal matrix that
//! couple each line (a particle component across a motion's frames),
//! inverted exactly by dense Cholesky.

use super::rows::{Rows, column_entry};
use crate::linalg::dense::{cholesky_in_place, cholesky_solve};
use crate::linalg::{Precond, Sequential, Space};
use crate::math::Real;
use rayon::prelude::*;

/// Rows of a block that spans frames (a keyframe, velocity, obstacle or
/// acceleration block has one per dimension, or one per obstacle) that
/// the preconditioner couples across frames; larger ones, which no
/// energy here makes, would count only on the diagonal.
const MAX_ROWS: usize = 8;

/// The blocks of `J^T J + mu D` that couple the unknowns of one line
/// (a particle component across a motion's frames), Cholesky-factored:
/// the acceleration terms couple frames only along lines, so their
/// stiffness, which grows as frames crowd together, is inverted exactly
/// and conjugate gradients see only the spatial coupling. With one frame
/// this is the diagonal (Jacobi) preconditioner.
#[derive(Debug)]
pub(super) struct LineBlocks {
    lines: usize,
    /// Unknowns per line.
    length: usize,
    /// `J^T J` restricted to each line, `length x length`, row-major.
    blocks: Vec<Real>,
    /// Their Cholesky factors with the damping added.
    factors: Vec<Real>,
}

impl LineBlocks {
    /// Blocks for `n` unknowns in `lines` lines.
    pub(super) fn new(lines: usize, n: usize) -> Self {
        let length = n.div_ceil(lines.max(1));
        Self {
            lines,
            length,
            blocks: vec![0.0; lines * length * length],
            factors: vec![0.0; lines * length * length],
        }
    }

    /// Accumulates the line blocks from `J`'s blocks; the diagonal is
    /// `diag` (already floored).
    pub(super) fn assemble(&mut self, j: &Rows, diag: &[Real]) {
        let (lines, length) = (self.lines, self.length);
        let size = length * length;
        self.blocks.fill(0.0);
        if length > 1 {
            let count = j.blocks.len();
            let chunk = count.div_ceil(rayon::current_num_threads().max(1)).max(1);
            let partial: Vec<Vec<Real>> = (0..count.div_ceil(chunk))
                .into_par_iter()
                .map(|c| {
                    let mut blocks = vec![0.0; lines * size];
                    // (line, frame, column of J within the block).
                    let mut columns: Vec<(u32, u32, [Real; MAX_ROWS])> = Vec::new();
                    for b in c * chunk..((c + 1) * chunk).min(count) {
                        let (rows, stencil) = j.ranges(b);
                        let block = j.blocks[b];
                        // A block within one frame adds only to diagonals.
                        let frame = |s: usize| j.bases[s] as usize / lines;
                        let first = frame(stencil.start);
                        if stencil.clone().all(|s| frame(s) == first) || rows.len() > MAX_ROWS {
                            continue;
                        }
                        let (dim, p) = (usize::from(block.dim), block.features());
                        let m = j.matrix_of(b, rows.len());
                        columns.clear();
                        for s in stencil {
                            let base = j.bases[s] as usize;
                            let w = j.weights_of(b, s);
                            for a in 0..dim {
                                let mut column = [0.0; MAX_ROWS];
                                for (v, row) in column.iter_mut().zip(m.chunks_exact(p)) {
                                    *v = column_entry(row, a, w);
                                }
                                let c = base + a;
                                columns.push(((c % lines) as u32, (c / lines) as u32, column));
                            }
                        }
                        columns.sort_unstable_by_key(|e| (e.0, e.1));
                        let mut start = 0;
                        while start < columns.len() {
                            let line = columns[start].0;
                            let end =
                                start + columns[start..].iter().take_while(|e| e.0 == line).count();
                            let block = &mut blocks[line as usize * size..][..size];
                            for x in &columns[start..end] {
                                for y in &columns[start..end] {
                                    if x.1 != y.1 {
                                        block[x.1 as usize * length + y.1 as usize] +=
                                            Sequential::dot(&x.2[..rows.len()], &y.2[..rows.len()]);
                                    }
                                }
                            }
                            start = end;
                        }
                    }
                    blocks
                })
                .collect();
            for p in partial {
                for (b, v) in self.blocks.iter_mut().zip(p) {
                    *b += v;
                }
            }
        }
        for (c, d) in diag.iter().enumerate() {
            let (line, at) = (c % lines, c / lines);
            self.blocks[line * size + at * length + at] = *d;
        }
        // Unknowns past the end of the last line (none in practice) keep
        // a unit diagonal so every block is definite.
        for c in diag.len()..lines * length {
            let (line, at) = (c % lines, c / lines);
            self.blocks[line * size + at * length + at] = 1.0;
        }
    }

    /// Factors each block with `mu D` added to its diagonal.
    pub(super) fn factor(&mut self, diag: &[Real], mu: Real) {
        let (lines, length) = (self.lines, self.length);
        let size = length * length;
        self.factors
            .par_chunks_mut(size)
            .zip(self.blocks.par_chunks(size))
            .enumerate()
            .for_each(|(line, (f, b))| {
                f.copy_from_slice(b);
                for at in 0..length {
                    let c = at * lines + line;
                    let d = diag.get(c).copied().unwrap_or(1.0);
                    f[at * length + at] += mu * d;
                }
                cholesky_in_place(f, length);
            });
    }
}

impl Precond<Real> for LineBlocks {
    /// `z = B^-1 r`, line by line.
    fn apply(&self, r: &[Real], z: &mut [Real]) {
        let (lines, length) = (self.lines, self.length);
        let size = length * length;
        if length == 1 {
            for ((z, r), f) in z.iter_mut().zip(r).zip(&self.factors) {
                *z = r / (f * f);
            }
            return;
        }
        let solved: Vec<Vec<Real>> = self
            .factors
            .par_chunks(size)
            .enumerate()
            .map(|(line, f)| {
                let mut y: Vec<Real> = (0..length)
                    .map(|at| r.get(at * lines + line).copied().unwrap_or(0.0))
                    .collect();
                cholesky_solve(f, length, &mut y);
                y
            })
            .collect();
        for (line, y) in solved.iter().enumerate() {
            for (at, v) in y.iter().enumerate() {
                if let Some(z) = z.get_mut(at * lines + line) {
                    *z = *v;
                }
            }
        }
    }
}
