//! Implicit surfaces: what the Element-Free Galerkin discretisation asks
//! of a closed surface (Guo–Qin, Section 4.1), whatever it was built
//! from. The octree classifies its octants by the sign of the field, the
//! exterior-boundary nodes are projected onto the zero set, and the
//! quadrature drops the points that lie outside.
//!
//! A closed triangle mesh answers through its exact signed distance
//! ([`MeshSdf`]); an oriented point cloud through the field fitted to its
//! points (`points_implicit.rs`); a sphere through its own ([`Ball`]), so
//! that a spherical solid is a sphere and not the polyhedron a display
//! mesh approximates it by.

use super::MeshSdf;
use crate::math::{Real, Vector};

/// A closed surface given by a signed field: negative inside, zero on the
/// surface, positive outside, with (approximately) unit gradient near the
/// surface so that its value reads as a distance there. Queries run from
/// any number of threads.
pub trait ImplicitSurface: Sync {
    /// Signed distance from `p` to the surface, negative inside: exact for
    /// a mesh, an estimate near the surface for a point cloud.
    fn signed_distance(&self, p: &Vector) -> Real;

    /// Unit outward normal of the level set through `p`.
    fn normal(&self, p: &Vector) -> Vector;

    /// The point of the surface nearest `p` (for a point cloud: where
    /// Newton steps along the gradient reach the zero set).
    fn project(&self, p: &Vector) -> Vector;

    /// Axis-aligned box `(min, max)` holding the whole surface.
    fn bounds(&self) -> (Vector, Vector);

    /// Whether `p` lies inside (or on) the surface.
    fn contains(&self, p: &Vector) -> bool {
        self.signed_distance(p) <= 0.0
    }
}

impl ImplicitSurface for MeshSdf {
    fn signed_distance(&self, p: &Vector) -> Real {
        self.distance(p)
    }

    fn normal(&self, p: &Vector) -> Vector {
        self.gradient(p)
    }

    fn project(&self, p: &Vector) -> Vector {
        self.closest(p).point
    }

    fn bounds(&self) -> (Vector, Vector) {
        MeshSdf::bounds(self)
    }
}

/// A sphere as its exact signed distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ball {
    /// The centre.
    pub centre: Vector,
    /// The radius.
    pub radius: Real,
}

impl ImplicitSurface for Ball {
    fn signed_distance(&self, p: &Vector) -> Real {
        (p - self.centre).norm() - self.radius
    }

    /// The radial direction; `+z` at the centre, where every direction is
    /// the gradient's limit.
    fn normal(&self, p: &Vector) -> Vector {
        (p - self.centre)
            .try_normalize(0.0)
            .unwrap_or_else(Vector::z)
    }

    fn project(&self, p: &Vector) -> Vector {
        self.centre + self.normal(p) * self.radius
    }

    fn bounds(&self) -> (Vector, Vector) {
        (
            self.centre - Vector::repeat(self.radius),
            self.centre + Vector::repeat(self.radius),
        )
    }
}
