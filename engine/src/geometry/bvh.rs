//! A bounding-volume hierarchy of axis-aligned boxes over triangles, for
//! nearest-triangle queries in O(log n): built top-down by median split of
//! the centroids along the longest axis, searched best-first with pruning
//! by the box distance.

use crate::math::{Real, Vector};

/// Triangles per leaf: a few, so that leaf tests amortise box tests.
const LEAF_SIZE: usize = 4;

#[derive(Debug, Clone, Copy)]
struct Node {
    min: Vector,
    max: Vector,
    /// Leaf: first entry in `items`; inner: index of the right child (the
    /// left child follows its parent).
    start: u32,
    /// Items in a leaf; 0 marks an inner node.
    count: u32,
}

impl Node {
    /// Squared distance from `p` to the box (0 inside).
    fn distance_squared(&self, p: &Vector) -> Real {
        (0..3)
            .map(|a| {
                let d = (self.min[a] - p[a]).max(p[a] - self.max[a]).max(0.0);
                d * d
            })
            .sum()
    }
}

#[derive(Debug, Clone)]
pub struct Bvh {
    nodes: Vec<Node>,
    items: Vec<u32>,
}

impl Bvh {
    /// Builds the hierarchy over items given by their bounding boxes.
    pub fn new(boxes: &[(Vector, Vector)]) -> Bvh {
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * boxes.len() / LEAF_SIZE + 1),
            items: (0..boxes.len() as u32).collect(),
        };
        let centroids: Vec<Vector> = boxes.iter().map(|(lo, hi)| (lo + hi) / 2.0).collect();
        if !boxes.is_empty() {
            bvh.build(boxes, &centroids, 0, boxes.len());
        }
        bvh
    }

    /// Builds the subtree over `items[start..end]` and returns its index.
    fn build(
        &mut self,
        boxes: &[(Vector, Vector)],
        centroids: &[Vector],
        start: usize,
        end: usize,
    ) -> usize {
        let items = &mut self.items[start..end];
        let (mut min, mut max) = boxes[items[0] as usize];
        let (mut cmin, mut cmax) = (centroids[items[0] as usize], centroids[items[0] as usize]);
        for &i in items.iter() {
            let (lo, hi) = &boxes[i as usize];
            min = min.inf(lo);
            max = max.sup(hi);
            cmin = cmin.inf(&centroids[i as usize]);
            cmax = cmax.sup(&centroids[i as usize]);
        }
        let index = self.nodes.len();
        self.nodes.push(Node {
            min,
            max,
            start: start as u32,
            count: items.len() as u32,
        });
        if items.len() <= LEAF_SIZE {
            return index;
        }
        let axis = (cmax - cmin).imax();
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |&a, &b| {
            centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
        });
        self.build(boxes, centroids, start, start + mid);
        let right = self.build(boxes, centroids, start + mid, end);
        self.nodes[index].start = right as u32;
        self.nodes[index].count = 0;
        index
    }

    /// The item nearest to `p`, where `measure(item)` gives an item's
    /// squared distance and whatever else the caller wants kept with it;
    /// `None` when empty. Children are visited nearer box first and
    /// skipped once their box is farther than the best item so far.
    pub fn nearest<T>(
        &self,
        p: &Vector,
        mut measure: impl FnMut(u32) -> (Real, T),
    ) -> Option<(u32, Real, T)> {
        let mut best: Option<(u32, Real, T)> = None;
        let mut best_d2 = Real::INFINITY;
        // Median splits keep the depth at most log2(n) + 1 <= 33 for u32
        // items, and the stack holds at most one entry per level plus one.
        let mut stack = [(0_u32, 0.0); 64];
        stack[0] = (0, self.nodes.first()?.distance_squared(p));
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (index, bound) = stack[top];
            if bound >= best_d2 {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.count > 0 {
                let start = node.start as usize;
                for &item in &self.items[start..start + node.count as usize] {
                    let (d2, extra) = measure(item);
                    if d2 < best_d2 {
                        best_d2 = d2;
                        best = Some((item, d2, extra));
                    }
                }
                continue;
            }
            let (left, right) = (index + 1, node.start);
            let dl = self.nodes[left as usize].distance_squared(p);
            let dr = self.nodes[right as usize].distance_squared(p);
            // Pushed last is popped first: the nearer child.
            let (near, far) = if dl < dr {
                ((left, dl), (right, dr))
            } else {
                ((right, dr), (left, dl))
            };
            stack[top] = far;
            stack[top + 1] = near;
            top += 2;
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform;

    /// Nearest of random points to random query points, against a scan.
    #[test]
    fn nearest_point_matches_a_linear_scan() {
        let mut seed = 5;
        for n in [1, 3, 4, 5, 17, 1000] {
            let points: Vec<Vector> = (0..n)
                .map(|_| Vector::new(uniform(&mut seed), uniform(&mut seed), uniform(&mut seed)))
                .collect();
            let boxes: Vec<(Vector, Vector)> = points.iter().map(|p| (*p, *p)).collect();
            let bvh = Bvh::new(&boxes);
            for _ in 0..200 {
                let q = Vector::new(uniform(&mut seed), uniform(&mut seed), uniform(&mut seed))
                    * 1.4
                    - Vector::repeat(0.2);
                let (item, d2, ()) = bvh
                    .nearest(&q, |i| ((points[i as usize] - q).norm_squared(), ()))
                    .expect("not empty");
                let scan = points
                    .iter()
                    .map(|p| (p - q).norm_squared())
                    .fold(Real::INFINITY, Real::min);
                assert_eq!(d2, scan, "n = {n}");
                assert_eq!((points[item as usize] - q).norm_squared(), scan);
            }
        }
        assert!(
            Bvh::new(&[])
                .nearest(&Vector::zeros(), |_| (0.0, ()))
                .is_none()
        );
    }
}
