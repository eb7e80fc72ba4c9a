//! What a modal solid will hold, bounded from its octree before anything
//! that grows with it is built, so that a host can refuse a precompute
//! it has no memory for instead of finding out gigabytes in.
//!
//! The octree fixes the node count and, for each leaf, the nodes whose
//! supports may reach it (a superset of those that do), and every count
//! the rest of the build makes is bounded by them:
//!
//! - quadrature points: the Gauss points of every non-exterior leaf
//!   before those outside the surface are dropped
//!   ([`Quadrature::most_points`]);
//! - shape-function entries: each point's row holds only candidates of
//!   its leaf, so at most `points x candidates` per leaf, and a surface
//!   point (anchor, skin vertex) at most its leaf's candidates;
//! - blocks of M and K: two nodes couple only through a point both
//!   supports cover, so node `n`'s column holds at most the union of the
//!   candidates of the leaves `n` is a candidate of;
//! - the modal bases: `3 n x modes` twice, and the eigensolver's Krylov
//!   basis beside them.
//!
//! Priced at [`super::ModalSolid::bytes`]'s rates, plus what the build
//! holds for a moment: each table's rows as they are computed, before
//! they are packed (as many bytes again), the tables of the skin and of
//! the nodes' own positions, the Krylov basis. Not modelled: the sparse
//! Cholesky factor of the shift-invert eigensolver, whose fill-in the
//! octree does not tell. The tests build several solids and check that
//! the estimate is above their count and within a small factor of it.

use super::quadrature::Quadrature;
use super::solid::EfgParams;
use crate::cancel::{Cancel, Cancelled};
use crate::geometry::octree::{OctantKind, Octree};
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// Nodes per parallel task of the coupling count, each with its own
/// marks: some milliseconds of work between two reads of the flag.
const NODES_PER_TASK: usize = 1024;

/// Bytes per shape-function entry of the quadrature and fixed tables: a
/// value and a gradient (four reals) and a node index.
pub(super) const SHAPE_ENTRY_BYTES: usize = 4 * std::mem::size_of::<Real>() + 4;

/// Bytes per scalar entry of M and K: their two values and the pattern's
/// row index.
pub(super) const MATRIX_ENTRY_BYTES: usize = 2 * std::mem::size_of::<Real>() + 4;

/// Per-node state of a stepping modal solid (displacements, rotations,
/// loads, scratch), in reals.
pub(super) const NODE_REALS: usize = 24;

/// An upper bound on what a modal solid holds, from its octree.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Estimate {
    /// Nodes (exact).
    pub nodes: usize,
    /// Quadrature points, at most.
    pub quadrature_points: usize,
    /// Shape-function entries of the quadrature and the fixed surface, at
    /// most.
    pub shape_entries: usize,
    /// 3x3 blocks of M and K (lower triangle), at most.
    pub blocks: usize,
    /// Modes kept.
    pub modes: usize,
    /// Bytes, at most (see the module's notes).
    pub bytes: u64,
}

/// The surface points a solid interpolates besides its quadrature.
#[derive(Debug, Clone, Copy)]
pub(super) struct SurfacePoints<'a> {
    /// Anchored points (penalty).
    pub fixed: &'a [Vector],
    /// Skin vertices.
    pub skin: &'a [Vector],
    /// Skin triangles.
    pub triangles: usize,
}

impl Estimate {
    /// The bound for a solid on `octree` with `params`, `modes` modes and
    /// the surface points `surface`. Reads `cancel` once per task.
    ///
    /// # Errors
    /// [`Cancelled`] once `cancel` is raised.
    pub(super) fn of(
        octree: &Octree,
        params: &EfgParams,
        modes: usize,
        surface: SurfacePoints<'_>,
        cancel: &Cancel,
    ) -> Result<Self, Cancelled> {
        let nodes = octree.nodes().len();
        let leaves = octree.leaves();
        let (mut quadrature_points, mut shape_entries) = (0usize, 0usize);
        for (i, leaf) in leaves.iter().enumerate() {
            let points = Quadrature::most_points(
                leaf,
                params.quadrature_order,
                params.subdivision,
                params.boundary_refinement,
            );
            quadrature_points = quadrature_points.saturating_add(points);
            shape_entries = shape_entries
                .saturating_add(points.saturating_mul(octree.candidates(i as u32).len()));
        }
        let row = |p: &Vector| octree.leaf_at(p).map_or(0, |l| octree.candidates(l).len());
        shape_entries = shape_entries.saturating_add(surface.fixed.iter().map(row).sum());
        let skin_entries: usize = surface.skin.iter().map(row).sum();
        let node_entries: usize = octree.nodes().iter().map(|n| row(&n.position)).sum();
        let blocks = blocks(octree, cancel)?;
        let real = std::mem::size_of::<Real>();
        let skin = skin_entries * 8 + surface.skin.len() * (6 * real + 8) + 36 * surface.triangles;
        let total = [
            octree.bytes(),
            blocks.saturating_mul(9 * MATRIX_ENTRY_BYTES + 4),
            // Psi and W, and the eigensolver's Krylov basis.
            nodes.saturating_mul(
                3 * (2 * modes + crate::linalg::eigen::basis_vectors(modes)) * real,
            ),
            // The packed table and, while it is built, its rows.
            shape_entries.saturating_mul(2 * SHAPE_ENTRY_BYTES),
            // The quadrature's points and weights.
            quadrature_points.saturating_mul(4 * real),
            skin,
            // While they are built: the tables of the skin's vertices and
            // of the nodes (for the rotation modes), rows and packed.
            (skin_entries + node_entries).saturating_mul(2 * SHAPE_ENTRY_BYTES),
            nodes * NODE_REALS * real,
        ]
        .into_iter()
        .fold(0usize, usize::saturating_add);
        Ok(Self {
            nodes,
            quadrature_points,
            shape_entries,
            blocks,
            modes,
            bytes: total as u64,
        })
    }
}

/// At most how many blocks `m >= n` the columns of M and K hold: for each
/// node the union of the candidates of the leaves it may reach.
fn blocks(octree: &Octree, cancel: &Cancel) -> Result<usize, Cancelled> {
    let nodes = octree.nodes().len();
    let leaves = octree.leaves();
    // Each node's leaves: the candidate lists transposed.
    let mut offsets = vec![0usize; nodes + 1];
    let reached = |i: usize| {
        let leaf = &leaves[i];
        let none: &[u32] = &[];
        if leaf.kind == OctantKind::Exterior {
            none
        } else {
            octree.candidates(i as u32)
        }
    };
    for i in 0..leaves.len() {
        for &n in reached(i) {
            offsets[n as usize + 1] += 1;
        }
    }
    for n in 0..nodes {
        offsets[n + 1] += offsets[n];
    }
    let mut next = offsets.clone();
    let mut by_node = vec![0u32; offsets[nodes]];
    for i in 0..leaves.len() {
        for &n in reached(i) {
            by_node[next[n as usize]] = i as u32;
            next[n as usize] += 1;
        }
    }
    let starts: Vec<usize> = (0..nodes).step_by(NODES_PER_TASK).collect();
    starts
        .par_iter()
        .map(|&start| {
            cancel.check()?;
            // `mark[m] == n + 1`: node m is already counted for n.
            let mut mark = vec![0u32; nodes];
            let mut count = 0usize;
            for n in start..(start + NODES_PER_TASK).min(nodes) {
                // The diagonal block, which every column holds.
                count += 1;
                for &leaf in &by_node[offsets[n]..offsets[n + 1]] {
                    for &m in octree.candidates(leaf) {
                        let m = m as usize;
                        if m > n && mark[m] != n as u32 + 1 {
                            mark[m] = n as u32 + 1;
                            count += 1;
                        }
                    }
                }
            }
            Ok(count)
        })
        .try_reduce(|| 0, |a, b| Ok(a + b))
}
