//! Distances *inside* the shape (Adams et al. 2008, in the tutorial's
//! Section 8.1): two points couple only when the straight segment between
//! them stays inside the shape, the visibility criterion of the
//! element-free Galerkin method (Belytschko et al. 1994). So two fingers
//! that nearly touch, close in space but far apart along the shape, do
//! not drag each other along, while inside a convex neighbourhood the
//! coupling distance is the Euclidean one and the MLS shape functions keep
//! their exact linear reproduction.
//!
//! The shape's signed distance is sampled once on a grid a quarter of a
//! spacing fine and interpolated, so a mesh shape with a 100k-vertex
//! surface costs one grid lookup per test, not a BVH query. Segments are
//! marched with steps set by the distance (sphere tracing: a point at
//! depth `d` has no surface within `d`), a few lookups per segment.

use super::DesignError;
use crate::geometry::Shape;
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// Grid cells across the longest side at most: 2^21 nodes in 3D.
const MAX_CELLS: usize = 128;

/// A shape placed in the world, its signed distance sampled on a grid.
#[derive(Debug, Clone)]
pub struct Inside {
    dim: usize,
    origin: Vector,
    cell: Real,
    counts: [usize; 3],
    values: Vec<Real>,
    /// How far outside a point may be and still count as inside: surface
    /// vertices sit on the boundary, and a faceted mesh strays from it.
    tolerance: Real,
}

impl Inside {
    /// Samples `shape` (body frame), placed at `centre` turned by
    /// `rotation`, for a design spacing `spacing`.
    ///
    /// # Errors
    /// [`DesignError::Parameter`] for an unbounded shape.
    pub fn new(
        shape: &Shape,
        centre: Vector,
        rotation: nalgebra::Rotation3<Real>,
        dim: usize,
        spacing: Real,
    ) -> Result<Self, DesignError> {
        let reach = shape.bounding_radius(dim);
        if !reach.is_finite() {
            return Err(DesignError::Parameter {
                field: "shape",
                message: "a plane has no inside to design; use a bounded shape".into(),
            });
        }
        let margin = reach + spacing;
        let cell = (spacing / 4.0).max(2.0 * margin / MAX_CELLS as Real);
        let mut counts = [1usize; 3];
        for c in counts.iter_mut().take(dim) {
            *c = (2.0 * margin / cell).ceil() as usize + 1;
        }
        let origin = Vector::from_fn(|a, _| if a < dim { centre[a] - margin } else { 0.0 });
        let inverse = rotation.inverse();
        let values = (0..counts[0] * counts[1] * counts[2])
            .into_par_iter()
            .map(|k| {
                let node = [
                    k % counts[0],
                    (k / counts[0]) % counts[1],
                    k / (counts[0] * counts[1]),
                ];
                let p = origin + Vector::from_fn(|a, _| node[a] as Real * cell);
                shape.signed_distance(&(inverse * (p - centre)), dim)
            })
            .collect();
        Ok(Self {
            dim,
            origin,
            cell,
            counts,
            values,
            tolerance: 0.25 * spacing,
        })
    }

    /// The interpolated signed distance at `p` (world), negative inside;
    /// outside the grid, the distance to it plus the value at its border.
    pub fn distance(&self, p: &Vector) -> Real {
        let mut base = [0usize; 3];
        let mut frac = [0.0; 3];
        let mut outside = 0.0;
        for a in 0..self.dim {
            let g = (p[a] - self.origin[a]) / self.cell;
            let top = (self.counts[a] - 1) as Real;
            let clamped = g.clamp(0.0, top);
            outside += ((g - clamped) * self.cell).powi(2);
            let b = (clamped.floor() as usize).min(self.counts[a].saturating_sub(2));
            base[a] = b;
            frac[a] = clamped - b as Real;
        }
        let at = |i: usize, j: usize, k: usize| {
            self.values[i + self.counts[0] * (j + self.counts[1] * k)]
        };
        let corners = if self.dim == 3 { 8 } else { 4 };
        let mut value = 0.0;
        for c in 0..corners {
            let bit = |a: usize| (c >> a) & 1;
            let w: Real = frac[..self.dim]
                .iter()
                .enumerate()
                .map(|(a, f)| if bit(a) == 1 { *f } else { 1.0 - f })
                .product();
            let idx = |a: usize| if a < self.dim { base[a] + bit(a) } else { 0 };
            value += w * at(idx(0), idx(1), idx(2));
        }
        value + outside.sqrt()
    }

    /// Whether `p` is inside, within the tolerance.
    pub fn contains(&self, p: &Vector) -> bool {
        self.distance(p) <= self.tolerance
    }

    /// Whether the segment from `a` to `b` stays inside, within the
    /// tolerance.
    pub fn sees(&self, a: &Vector, b: &Vector) -> bool {
        let length = (b - a).norm();
        if !length.is_finite() {
            return false;
        }
        let min_step = 0.05 * self.tolerance.max(Real::MIN_POSITIVE);
        let mut t = 0.0;
        loop {
            let p = a + (b - a) * (t / length.max(Real::MIN_POSITIVE));
            let d = self.distance(&p);
            if d > self.tolerance {
                return false;
            }
            if t >= length {
                return true;
            }
            t = (t + (self.tolerance - d).max(min_step)).min(length);
        }
    }
}
