//! Collisions of solid particles with rigid obstacles (signed distance
//! fields of [`Shape`]s) and the walls of the domain.
//!
//! A particle is a ball of radius `spacing / 2`. Two treatments:
//!
//! - **Projection** (explicit steps): one that ends a sub-step closer than
//!   that to an obstacle is projected back onto the offset surface, its
//!   approaching normal velocity is removed (no bounce), and its
//!   tangential velocity loses up to `friction` times the removed normal
//!   speed (Coulomb). Its sub-steps are short, so each correction is
//!   small.
//! - **Penalty inside the solve** ([`Penalty`], implicit steps): the
//!   overlap `d` stores `k d^2 / 2`, part of the energy backward Euler
//!   minimises, so contact is one more conservative force that the
//!   Newton step and its line search see. Projecting after a long
//!   implicit step instead moved the bottom row of a resting block by
//!   the step's whole fall `dt^2 g` and stored that strain: a 2D block at
//!   E = 1e5 Pa gained 38 % of its energy scale, one at 1e7 Pa 41 times
//!   it, and settled squeezed by 5 %. Friction then takes, from the
//!   tangential velocity, up to `friction` times the normal impulse the
//!   penalty gave. Only a particle whose centre crossed the surface (a
//!   step that tunnels) is still projected.

use crate::geometry::Shape;
use crate::math::{Real, Vector};
use nalgebra::{Matrix3, UnitQuaternion};
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
    /// Whether there is nothing to collide with.
    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty() && self.walls.is_none()
    }

    /// Calls `contact(n, d)` for each obstacle or wall a ball of `radius`
    /// at `x` overlaps, with the outward unit normal `n` and the overlap
    /// `d > 0`.
    pub fn overlaps(
        &self,
        dim: usize,
        radius: Real,
        x: &Vector,
        mut contact: impl FnMut(Vector, Real),
    ) {
        for o in &self.shapes {
            let local = o.orientation.inverse() * (*x - o.position);
            let depth = radius - o.shape.signed_distance(&local, dim);
            if depth > 0.0 {
                contact(o.orientation * o.shape.normal(&local, dim), depth);
            }
        }
        if let Some((min, max)) = &self.walls {
            for a in 0..dim {
                let mut n = Vector::zeros();
                let below = min[a] + radius - x[a];
                let above = x[a] - (max[a] - radius);
                if below > 0.0 {
                    n[a] = 1.0;
                    contact(n, below);
                } else if above > 0.0 {
                    n[a] = -1.0;
                    contact(n, above);
                }
            }
        }
    }

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

/// Penalty contact for an implicit step of length `h`: each particle's
/// overlap `d` stores `k_i d^2 / 2` with
/// `k_i = max(100 m_i / h^2, E dx^(dim - 2))`.
/// The first keeps the overlap a small fraction of a step's motion at
/// short steps; the second keeps it near what the bottom row's own
/// compression is at long ones (the static scheme's step is seconds).
#[derive(Debug, Clone, Copy)]
pub struct Penalty<'a> {
    obstacles: &'a Obstacles,
    dim: usize,
    radius: Real,
    /// `k_i / m_i` at short steps.
    per_mass: Real,
    /// `k_i` at long steps.
    floor: Real,
}

/// `k h^2 / m`: the contact's weight in the step's Hessian against the
/// particle's mass.
const STIFFNESS_PER_STEP: Real = 100.0;
/// Contact stiffness against a particle-sized spring of the material:
/// as stiff, so the bottom row overlaps the floor by about what it
/// compresses itself (0.6 % of a particle radius for a 0.2 m block at
/// E = 1e5 Pa), and the contact conditions Newton no worse than the
/// material does.
const STIFFNESS_PER_MODULUS: Real = 1.0;

impl<'a> Penalty<'a> {
    /// The penalty for a body of `dim`, particle `spacing` and Young's
    /// modulus `young`, stepped by `h`; `None` without obstacles.
    pub fn new(
        obstacles: &'a Obstacles,
        dim: usize,
        spacing: Real,
        young: Real,
        h: Real,
    ) -> Option<Self> {
        (!obstacles.is_empty()).then(|| Self {
            obstacles,
            dim,
            radius: 0.5 * spacing,
            per_mass: STIFFNESS_PER_STEP / (h * h),
            floor: STIFFNESS_PER_MODULUS * young * spacing.powi(dim as i32 - 2),
        })
    }

    /// The stiffness `k_i` of a particle of mass `m`.
    pub fn stiffness(&self, mass: Real) -> Real {
        (self.per_mass * mass).max(self.floor)
    }

    /// The energy a particle of mass `m` at `x` stores, J.
    pub fn energy(&self, mass: Real, x: &Vector) -> Real {
        let mut sum = 0.0;
        self.obstacles
            .overlaps(self.dim, self.radius, x, |_, d| sum += d * d);
        0.5 * self.stiffness(mass) * sum
    }

    /// The force on a particle of mass `m` at `x`, N.
    pub fn force(&self, mass: Real, x: &Vector) -> Vector {
        let mut f = Vector::zeros();
        self.obstacles
            .overlaps(self.dim, self.radius, x, |n, d| f += n * d);
        f * self.stiffness(mass)
    }

    /// The force's negative derivative `k sum n n^T` at `x` (the
    /// surface's curvature left out, exact for walls and planes).
    pub fn stiffness_matrix(&self, mass: Real, x: &Vector) -> Matrix3<Real> {
        let mut k = Matrix3::zeros();
        self.obstacles
            .overlaps(self.dim, self.radius, x, |n, _| k += n * n.transpose());
        k * self.stiffness(mass)
    }

    /// After the step: friction against the normal impulse `h f` each
    /// overlapping particle received, and projection of the particles
    /// whose centre crossed a surface.
    pub fn finish(
        &self,
        h: Real,
        friction: Real,
        masses: &[Real],
        fixed: &[bool],
        x: &mut [Vector],
        v: &mut [Vector],
    ) {
        x.par_iter_mut()
            .zip(v.par_iter_mut())
            .zip(masses.par_iter().zip(fixed))
            .filter(|(_, (_, fixed))| !**fixed)
            .for_each(|((x, v), (&m, _))| {
                let mut crossed = None;
                self.obstacles.overlaps(self.dim, self.radius, x, |n, d| {
                    if friction > 0.0 {
                        let impulse = h * self.stiffness(m) * d / m;
                        slide(v, &n, friction * impulse);
                    }
                    if d > self.radius {
                        crossed = Some((n, d));
                    }
                });
                if let Some((n, d)) = crossed {
                    *x += n * (d - self.radius);
                    collide(v, &n, 0.0);
                }
            });
    }
}

/// Takes up to `loss` of the tangential velocity to the surface of normal
/// `n`.
fn slide(v: &mut Vector, n: &Vector, loss: Real) {
    let tangential = *v - n * v.dot(n);
    let speed = tangential.norm();
    if speed > 0.0 {
        *v -= tangential * (loss.min(speed) / speed);
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
    slide(v, n, friction * -vn);
}
