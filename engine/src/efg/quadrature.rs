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

pub use crate::approx::gauss::{MAX_ORDER, gauss_legendre};

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
