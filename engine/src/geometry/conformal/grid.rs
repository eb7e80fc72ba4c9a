//! A uniform grid over a chart's parametric box: each cell lists the
//! triangles and the boundary edges whose boxes meet it, so that finding
//! the triangle under a point and the nearest boundary edge reads a few
//! cells instead of the whole chart (a 50k-point surface is charted,
//! cut into a quadtree and sampled at every Gauss point through it).

use super::super::quadtree::Point2;
use crate::math::Real;

/// Triangles per cell the grid aims at.
const PER_CELL: Real = 2.0;

/// Rings of cells searched for a boundary edge before the distance is
/// given as a bound (a point that far out needs only to know it is far).
const MAX_RINGS: usize = 8;

/// Items listed per cell, compressed.
#[derive(Debug, Clone, Default)]
struct Lists {
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Lists {
    /// Lists `count` items by the cells `cells(k)` each item meets.
    fn new(grid: &ChartGrid, count: usize, cells: impl Fn(usize) -> (Point2, Point2)) -> Self {
        let total = grid.dims[0] * grid.dims[1];
        let mut counts = vec![0u32; total + 1];
        let range = |k: usize| {
            let (lo, hi) = cells(k);
            let (a, b) = (grid.clamped(lo), grid.clamped(hi));
            (a[0]..=b[0]).flat_map(move |i| (a[1]..=b[1]).map(move |j| (i, j)))
        };
        for k in 0..count {
            for (i, j) in range(k) {
                counts[grid.index(i, j) + 1] += 1;
            }
        }
        for c in 1..=total {
            counts[c] += counts[c - 1];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[total] as usize];
        for k in 0..count {
            for (i, j) in range(k) {
                let slot = &mut fill[grid.index(i, j)];
                items[*slot as usize] = k as u32;
                *slot += 1;
            }
        }
        Self {
            start: counts,
            items,
        }
    }

    fn at(&self, cell: usize) -> &[u32] {
        &self.items[self.start[cell] as usize..self.start[cell + 1] as usize]
    }
}

/// The grid (see the module's documentation).
#[derive(Debug, Clone, Default)]
pub(super) struct ChartGrid {
    lo: Point2,
    cell: Real,
    dims: [usize; 2],
    triangles: Lists,
    edges: Lists,
}

impl ChartGrid {
    /// The grid over `uv`'s box for `triangles` and the `boundary`
    /// edges.
    pub(super) fn new(uv: &[Point2], triangles: &[[u32; 3]], boundary: &[[u32; 2]]) -> Self {
        let (mut lo, mut hi) = ([Real::INFINITY; 2], [Real::NEG_INFINITY; 2]);
        for p in uv {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let extent = [(hi[0] - lo[0]).max(0.0), (hi[1] - lo[1]).max(0.0)];
        let area = (extent[0] * extent[1]).max(Real::MIN_POSITIVE);
        let cells = (triangles.len() as Real / PER_CELL).max(1.0);
        let mut cell = (area / cells).sqrt();
        if !(cell.is_finite() && cell > 0.0) {
            cell = extent[0].max(extent[1]).max(1.0);
        }
        let dims = extent.map(|e| ((e / cell).floor() as usize + 1).min(1 << 12));
        let mut grid = Self {
            lo,
            cell,
            dims,
            ..Self::default()
        };
        let bounds = |points: &[u32]| {
            let (mut a, mut b) = ([Real::INFINITY; 2], [Real::NEG_INFINITY; 2]);
            for &k in points {
                let p = uv[k as usize];
                for c in 0..2 {
                    a[c] = a[c].min(p[c]);
                    b[c] = b[c].max(p[c]);
                }
            }
            (a, b)
        };
        grid.triangles = Lists::new(&grid, triangles.len(), |k| bounds(&triangles[k]));
        grid.edges = Lists::new(&grid, boundary.len(), |k| bounds(&boundary[k]));
        grid
    }

    fn index(&self, i: usize, j: usize) -> usize {
        i * self.dims[1] + j
    }

    /// The cell holding `u`, clamped into the grid.
    fn clamped(&self, u: Point2) -> [usize; 2] {
        let at = |a: usize| {
            let t = ((u[a] - self.lo[a]) / self.cell).floor();
            if t.is_nan() || t < 0.0 {
                0
            } else {
                (t as usize).min(self.dims[a] - 1)
            }
        };
        [at(0), at(1)]
    }

    /// The triangles whose boxes meet the cell holding `u` (none outside
    /// the grid).
    pub(super) fn triangles_at(&self, u: Point2) -> &[u32] {
        let inside = (0..2).all(|a| {
            let t = (u[a] - self.lo[a]) / self.cell;
            t >= 0.0 && t <= self.dims[a] as Real
        });
        if !inside {
            return &[];
        }
        let [i, j] = self.clamped(u);
        self.triangles.at(self.index(i, j))
    }

    /// The boundary edge nearest `u` by `distance(edge)`, with that
    /// distance; or, when that is not settled within [`MAX_RINGS`] rings
    /// of cells, a lower bound of the distance.
    pub(super) fn nearest_edge(
        &self,
        u: Point2,
        distance: impl Fn(u32) -> Real,
    ) -> Result<(u32, Real), Real> {
        let [ci, cj] = self.clamped(u);
        let mut best: Option<(u32, Real)> = None;
        let rings = MAX_RINGS.min(self.dims[0].max(self.dims[1]));
        for ring in 0..=rings {
            // Everything past this ring lies at least `ring` cells away.
            if let Some((_, d)) = best
                && d <= ring.saturating_sub(1) as Real * self.cell
            {
                break;
            }
            let (i0, i1) = (ci.saturating_sub(ring), (ci + ring).min(self.dims[0] - 1));
            let (j0, j1) = (cj.saturating_sub(ring), (cj + ring).min(self.dims[1] - 1));
            for i in i0..=i1 {
                for j in j0..=j1 {
                    let on_ring = i.abs_diff(ci) == ring || j.abs_diff(cj) == ring;
                    if !on_ring {
                        continue;
                    }
                    for &e in self.edges.at(self.index(i, j)) {
                        let d = distance(e);
                        if best.is_none_or(|(_, b)| d < b) {
                            best = Some((e, d));
                        }
                    }
                }
            }
        }
        let all = rings == self.dims[0].max(self.dims[1]);
        let reach = rings as Real * self.cell;
        // Every edge lies in the grid's box, so a point outside it is at
        // least that far from all of them: without this a point far out
        // (clamped onto the grid's border cell) had a bound of a few cells
        // however far it was, and a quadtree over an atlas's plane kept
        // every leaf of the empty plane around the charts.
        let outside = self.box_distance(u);
        match best {
            Some((e, d)) if all || d <= reach => Ok((e, d)),
            Some((_, d)) => Err(d.min(reach).max(outside)),
            None => Err(reach.max(outside)),
        }
    }

    /// Distance from `u` to the grid's box (zero inside).
    fn box_distance(&self, u: Point2) -> Real {
        let gap = |a: usize| {
            let hi = self.lo[a] + self.dims[a] as Real * self.cell;
            (self.lo[a] - u[a]).max(u[a] - hi).max(0.0)
        };
        gap(0).hypot(gap(1))
    }
}
