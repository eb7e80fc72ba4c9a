//! A kd-tree (tutorial Algorithms 3-4): the particles split recursively at
//! the median of the widest axis until leaves hold at most [`LEAF_SIZE`]
//! points. Its leaves follow the particles, so a dense clump and a sparse
//! background cost the same per particle, where a grid of cell size r
//! scans many empty cells (sparse regions) or crowded ones (dense regions,
//! with a larger r).

use super::CandidateSearch;
use crate::math::{Real, Vector};

/// Most points per leaf: small enough that a leaf's bounding box is tight,
/// large enough that descending the tree costs less than scanning leaves.
const LEAF_SIZE: usize = 12;

/// A node: the tight bounding box of its points, `order[start..end]`, and
/// its children (`left == 0` for a leaf; the root is never a child).
#[derive(Debug, Clone, Copy)]
struct Node {
    min: Vector,
    max: Vector,
    start: u32,
    end: u32,
    left: u32,
    right: u32,
}

/// A kd-tree over a set of positions, queried with the radius given at
/// construction.
#[derive(Debug, Clone)]
pub struct KdTree {
    radius_squared: Real,
    /// Particle indices, permuted so that each node's points are contiguous.
    order: Vec<u32>,
    /// Nodes in depth-first order; the root is node 0.
    nodes: Vec<Node>,
}

impl KdTree {
    /// An empty tree for neighbour queries within `radius`.
    pub fn new(radius: Real) -> Self {
        Self {
            radius_squared: radius * radius,
            order: Vec::new(),
            nodes: Vec::new(),
        }
    }

    /// Algorithm 3: builds the subtree of `order[start..end]` and returns
    /// its node index. Median splits (`select_nth_unstable`, O(n) per
    /// level) keep the tree balanced whatever the distribution, and give a
    /// depth of at most log2(n / LEAF_SIZE) + 1.
    fn build(&mut self, positions: &[Vector], start: usize, end: usize) -> u32 {
        let (mut min, mut max) = (
            Vector::repeat(Real::INFINITY),
            Vector::repeat(Real::NEG_INFINITY),
        );
        for &i in &self.order[start..end] {
            min = min.inf(&positions[i as usize]);
            max = max.sup(&positions[i as usize]);
        }
        let index = self.nodes.len() as u32;
        self.nodes.push(Node {
            min,
            max,
            start: start as u32,
            end: end as u32,
            left: 0,
            right: 0,
        });
        if end - start > LEAF_SIZE {
            let axis = (max - min).imax();
            let mid = start + (end - start) / 2;
            // Splitting by count, not by value, so coincident points still
            // halve the range and the recursion ends.
            self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                positions[a as usize][axis].total_cmp(&positions[b as usize][axis])
            });
            let left = self.build(positions, start, mid);
            let right = self.build(positions, mid, end);
            let node = &mut self.nodes[index as usize];
            node.left = left;
            node.right = right;
        }
        index
    }

    /// Algorithm 4: descend into the children whose bounding box comes
    /// closer than the radius to `p`, and visit every point of the leaves
    /// reached.
    fn query(&self, node: u32, p: &Vector, visit: &mut impl FnMut(u32)) {
        let Some(n) = self.nodes.get(node as usize) else {
            return;
        };
        let gap = (n.min - p).sup(&(p - n.max)).sup(&Vector::zeros());
        if gap.norm_squared() >= self.radius_squared {
            return;
        }
        if n.left == 0 {
            for &j in &self.order[n.start as usize..n.end as usize] {
                visit(j);
            }
        } else {
            self.query(n.left, p, visit);
            self.query(n.right, p, visit);
        }
    }
}

impl CandidateSearch for KdTree {
    /// Rebuilds the tree from scratch (the positions move every step);
    /// the index and node buffers are reused, so only the first build, or
    /// one with more particles, allocates.
    fn rebuild(&mut self, positions: &[Vector]) {
        self.order.clear();
        self.order.extend(0..positions.len() as u32);
        self.nodes.clear();
        if !positions.is_empty() {
            self.build(positions, 0, positions.len());
        }
    }

    /// Visits a superset of the points within the radius: every point of
    /// every leaf whose bounding box comes closer than the radius to `p`.
    /// Testing each point here would double the distance tests, since
    /// [`super::NeighborList::build`] filters anyway.
    #[inline]
    fn for_each_candidate(&self, p: &Vector, mut visit: impl FnMut(u32)) {
        self.query(0, p, &mut visit);
    }
}
