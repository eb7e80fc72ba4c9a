//! A uniform grid over the cracks' bounding boxes, so that a pair asks
//! only the cracks near it whether they cross it: a solid shattered into
//! thousands of cracks would otherwise test every pair it reweighs
//! against every crack (a 25,600-particle plate with 2,467 cracks spent 2
//! s a step there).

use super::crack::Crack;
use crate::math::{Real, Vector};
use std::collections::HashMap;

/// Cells one crack may take; a crack whose box spans more (one running
/// across a 3D body) is kept in a list every query reads.
const MAX_CELLS_PER_CRACK: i64 = 4096;

/// Cracks by the grid cells their bounding boxes overlap.
#[derive(Debug, Default)]
pub(in crate::solid) struct CrackIndex {
    /// Set when there are too few cracks to index (at most [`Self::WORTH`]):
    /// then every query answers all of them.
    scan: Option<u32>,
    inv_cell: Real,
    cells: HashMap<[i64; 3], Vec<u32>>,
    large: Vec<u32>,
}

impl CrackIndex {
    /// Cracks past which indexing them pays: up to it a query answers
    /// them all, unindexed (with one running crack the index's build and
    /// lookups cost half the update again, `cargo bench --bench
    /// fracture`).
    const WORTH: usize = 32;

    /// The index of `cracks` with cells of side `cell` (the support
    /// radius: a pair's segment then meets at most two cells a side).
    pub(in crate::solid) fn new(cracks: &[Crack], cell: Real) -> Self {
        if cracks.len() <= Self::WORTH {
            return Self {
                scan: Some(cracks.len() as u32),
                ..Self::default()
            };
        }
        let mut index = Self {
            inv_cell: 1.0 / cell,
            ..Self::default()
        };
        for (k, crack) in cracks.iter().enumerate() {
            let (lo, hi) = crack.bounds();
            let (a, b) = (index.cell_of(&lo), index.cell_of(&hi));
            let count: i64 = (0..3).map(|d| b[d] - a[d] + 1).product();
            if count > MAX_CELLS_PER_CRACK {
                index.large.push(k as u32);
                continue;
            }
            for x in a[0]..=b[0] {
                for y in a[1]..=b[1] {
                    for z in a[2]..=b[2] {
                        index.cells.entry([x, y, z]).or_default().push(k as u32);
                    }
                }
            }
        }
        index
    }

    fn cell_of(&self, p: &Vector) -> [i64; 3] {
        p.map(|x| (x * self.inv_cell).floor() as i64).into()
    }

    /// Into `out`: the cracks whose boxes may meet the box of the segment
    /// `a`-`b`, ascending and each once, so that summing over them adds
    /// what summing over every crack adds, in the same order.
    pub(in crate::solid) fn near(&self, a: &Vector, b: &Vector, out: &mut Vec<u32>) {
        out.clear();
        if let Some(all) = self.scan {
            out.extend(0..all);
            return;
        }
        out.extend_from_slice(&self.large);
        let (lo, hi) = (self.cell_of(&a.inf(b)), self.cell_of(&a.sup(b)));
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    if let Some(list) = self.cells.get(&[x, y, z]) {
                        out.extend_from_slice(list);
                    }
                }
            }
        }
        out.sort_unstable();
        out.dedup();
    }
}
