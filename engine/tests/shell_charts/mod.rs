//! Charts the shell tests share: flat and analytic surfaces whose
//! parametric domain is a box.

// Each test file uses the charts it needs.
#![allow(dead_code)]

use meshless_engine::geometry::quadtree::{ChartDomain, Point2};
use meshless_engine::math::{Real, Vector};
use meshless_engine::shell::ShellSurface;

/// The signed distance to the box `lo..hi`.
pub fn box_distance(u: Point2, lo: Point2, hi: Point2) -> Real {
    let dx = (lo[0] - u[0]).max(u[0] - hi[0]);
    let dy = (lo[1] - u[1]).max(u[1] - hi[1]);
    let outside = (dx.max(0.0).powi(2) + dy.max(0.0).powi(2)).sqrt();
    if outside > 0.0 { outside } else { dx.max(dy) }
}

/// The unit square in the plane `z = 0`: a flat chart, lambda = 1.
pub struct UnitSquare;

impl ChartDomain for UnitSquare {
    fn distance(&self, u: Point2) -> Real {
        box_distance(u, [0.0, 0.0], [1.0, 1.0])
    }

    fn lambda(&self, _: Point2) -> Real {
        1.0
    }
}

impl ShellSurface for UnitSquare {
    fn position(&self, u: Point2) -> Vector {
        Vector::new(u[0], u[1], 0.0)
    }
}
