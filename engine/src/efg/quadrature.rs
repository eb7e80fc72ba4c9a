//! Gaussian quadrature on integration cells cut from the terminal
//! octants (Guo–Qin, Section 4.1.2, Fig. 4b).
//!
//! Each interior octant is split into `subdivision^3` cells and each
//! boundary octant into `refinement` times as many along each axis, each
//! cell carrying the tensor-product Gauss–Legendre rule of `order` points
//! per axis. A point outside the implicit surface is dropped, so a cut
//! cell integrates over the part of it inside the solid up to the
//! resolution of its points; `refinement` is where that resolution is
//! bought, at `refinement^3` times the points in every boundary octant
//! (the tests measure the volume of a ball both ways).

use crate::cancel::{Cancel, Cancelled};
use crate::geometry::ImplicitSurface;
use crate::geometry::octree::{Octant, OctantKind, Octree};
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// Most Gauss points per axis of a cell.
pub const MAX_ORDER: usize = 5;

/// Gauss–Legendre abscissae and weights on [-1, 1] for 1 to 5 points
/// (Abramowitz & Stegun, Table 25.4).
pub(super) fn gauss_legendre(order: usize) -> (&'static [Real], &'static [Real]) {
    const X1: [Real; 1] = [0.0];
    const W1: [Real; 1] = [2.0];
    const X2: [Real; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];
    const W2: [Real; 2] = [1.0, 1.0];
    const X3: [Real; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
    const W3: [Real; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
    const X4: [Real; 4] = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    const W4: [Real; 4] = [
        0.347_854_845_137_453_9,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_9,
    ];
    const X5: [Real; 5] = [
        -0.906_179_845_938_664,
        -0.538_469_310_105_683,
        0.0,
        0.538_469_310_105_683,
        0.906_179_845_938_664,
    ];
    const W5: [Real; 5] = [
        0.236_926_885_056_189_1,
        0.478_628_670_499_366_5,
        0.568_888_888_888_888_9,
        0.478_628_670_499_366_5,
        0.236_926_885_056_189_1,
    ];
    match order {
        1 => (&X1, &W1),
        2 => (&X2, &W2),
        3 => (&X3, &W3),
        4 => (&X4, &W4),
        _ => (&X5, &W5),
    }
}

/// Quadrature points inside the solid and their weights (volumes).
#[derive(Debug, Clone, Default)]
pub struct Quadrature {
    /// Positions.
    pub points: Vec<Vector>,
    /// Weights: the volume each point stands for.
    pub weights: Vec<Real>,
}

impl Quadrature {
    /// The rule over the octree's I, IB and EB octants with `order`
    /// (1..=[`MAX_ORDER`]) Gauss points per axis on `subdivision^3` cells
    /// per interior octant and `(refinement * subdivision)^3` per boundary
    /// octant, points outside `surface` dropped. Reads `cancel` once per
    /// octant (a boundary octant is up to 4,096 cells of signed
    /// distances).
    ///
    /// # Errors
    /// [`Cancelled`] once `cancel` is raised.
    pub fn build(
        octree: &Octree,
        surface: &dyn ImplicitSurface,
        order: usize,
        subdivision: usize,
        refinement: usize,
        cancel: &Cancel,
    ) -> Result<Self, Cancelled> {
        let (x, w) = gauss_legendre(order);
        let per_leaf: Vec<(Vec<Vector>, Vec<Real>)> = octree
            .leaves()
            .par_iter()
            .map(|leaf| -> Result<_, Cancelled> {
                cancel.check()?;
                let Some((cells, boundary)) = cells_of(leaf, subdivision, refinement) else {
                    return Ok((Vec::new(), Vec::new()));
                };
                let h = leaf.size / cells as Real;
                let mut points = Vec::with_capacity(cells.pow(3) * x.len().pow(3));
                let mut weights = Vec::with_capacity(points.capacity());
                for c in 0..cells.pow(3) {
                    let corner = leaf.min
                        + Vector::new(
                            (c % cells) as Real,
                            (c / cells % cells) as Real,
                            (c / cells / cells) as Real,
                        ) * h;
                    for (xi, wi) in x.iter().zip(w) {
                        for (xj, wj) in x.iter().zip(w) {
                            for (xk, wk) in x.iter().zip(w) {
                                let p =
                                    corner + Vector::new(1.0 + xi, 1.0 + xj, 1.0 + xk) * (0.5 * h);
                                if boundary && !surface.contains(&p) {
                                    continue;
                                }
                                points.push(p);
                                weights.push(wi * wj * wk * (0.5 * h).powi(3));
                            }
                        }
                    }
                }
                Ok((points, weights))
            })
            .collect::<Result<_, Cancelled>>()?;
        let mut rule = Self::default();
        for (points, weights) in per_leaf {
            rule.points.extend(points);
            rule.weights.extend(weights);
        }
        Ok(rule)
    }

    /// The points [`Self::build`] would place in `leaf` before it drops
    /// those outside the surface: an upper bound on its share, known
    /// before any point is made.
    pub fn most_points(
        leaf: &Octant,
        order: usize,
        subdivision: usize,
        refinement: usize,
    ) -> usize {
        cells_of(leaf, subdivision, refinement).map_or(0, |(cells, _)| (cells * order).pow(3))
    }

    /// The number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there is no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The volume the rule integrates over: the sum of its weights.
    pub fn volume(&self) -> Real {
        self.weights.iter().sum()
    }
}

/// Integration cells per axis of `leaf` and whether it is a boundary
/// octant (whose points outside the surface are dropped); `None` for an
/// exterior octant, which has none.
fn cells_of(leaf: &Octant, subdivision: usize, refinement: usize) -> Option<(usize, bool)> {
    match leaf.kind {
        OctantKind::Exterior => None,
        OctantKind::Interior => Some((subdivision, false)),
        OctantKind::InteriorBoundary | OctantKind::ExteriorBoundary => {
            Some((refinement * subdivision, true))
        }
    }
}
