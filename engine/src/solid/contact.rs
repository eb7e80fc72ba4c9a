//! Collisions of solid particles with rigid obstacles (signed distance
//! fields of [`Shape`]s) and the walls of the domain.
//!
//! A particle is a ball of radius `spacing / 2`. One that ends a step
//! closer than that to an obstacle is projected back onto the offset
//! surface, its approaching normal velocity is removed (no bounce), and
//! its tangential velocity loses up to `friction` times the removed
//! normal speed (Coulomb).

use crate::geometry::Shape;
use crate::math::{Real, Vector};
use nalgebra::UnitQuaternion;
use rayon::prelude::*;

/// A static obstacle: a shape placed in the world.
#[derive(Debug, Clone)]
pub struct Obstacle {
    /// The shape in its body frame.
    pub shape: Shape,
    /// Where the body frame's origin lies in the world, m.
    pub position: Vector,
    /// Rotation from the body frame to the world.
    pub orientation: UnitQuaternion<Real>,
}

/// Everything a solid collides with.
#[derive(Debug, Clone, Default)]
pub struct Obstacles {
    /// The static obstacles, each tested against every free particle.
    pub shapes: Vec<Obstacle>,
    /// The domain box `(min, max)`, whose walls are on the first `dim`
    /// axes; `None` for an unbounded solid.
    pub walls: Option<(Vector, Vector)>,
}

impl Obstacles {
    /// Pushes every free particle out of the obstacles and walls.
    pub fn resolve(
        &self,
        dim: usize,
        radius: Real,
        friction: Real,
        fixed: &[bool],
        x: &mut [Vector],
        v: &mut [Vector],
    ) {
        if self.shapes.is_empty() && self.walls.is_none() {
            return;
        }
        x.par_iter_mut()
            .zip(v.par_iter_mut())
            .zip(fixed.par_iter())
            .filter(|(_, fixed)| !**fixed)
            .for_each(|((x, v), _)| {
                for o in &self.shapes {
                    let local = o.orientation.inverse() * (*x - o.position);
                    let depth = radius - o.shape.signed_distance(&local, dim);
                    if depth > 0.0 {
                        let n = o.orientation * o.shape.normal(&local, dim);
                        *x += n * depth;
                        collide(v, &n, friction);
                    }
                }
                if let Some((min, max)) = &self.walls {
                    for a in 0..dim {
                        let mut n = Vector::zeros();
                        if x[a] < min[a] + radius {
                            x[a] = min[a] + radius;
                            n[a] = 1.0;
                        } else if x[a] > max[a] - radius {
                            x[a] = max[a] - radius;
                            n[a] = -1.0;
                        } else {
                            continue;
                        }
                        collide(v, &n, friction);
                    }
                }
            });
    }
}

/// Removes the velocity into the surface of normal `n` and applies
/// Coulomb friction to the rest.
fn collide(v: &mut Vector, n: &Vector, friction: Real) {
    let vn = v.dot(n);
    if vn >= 0.0 {
        return;
    }
    *v -= n * vn;
    let tangential = *v - n * v.dot(n);
    let speed = tangential.norm();
    if speed > 0.0 {
        let loss = (friction * -vn).min(speed);
        *v -= tangential * (loss / speed);
    }
}
