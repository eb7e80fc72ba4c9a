//! One rigid body in the fluid: its shape, how it moves (static,
//! kinematic or dynamic), its state, and the step of its motion.
//!
//! Dynamic bodies are integrated with symplectic Euler, like the fluid
//! (tutorial Eq. 58-59): `v += dt (F / M + g)`, `x += dt v`, and for the
//! rotation `omega += dt I^-1 (tau - omega x I omega)` (Euler's equations
//! in the world frame, `I = R I_body R^T`), then `q <- exp(omega dt) q`,
//! renormalised, so the orientation stays a unit quaternion.

use crate::geometry::Shape;
use crate::math::{Real, Vector};
use nalgebra::{Matrix3, UnitQuaternion};
use std::f64::consts::PI;

/// An orientation: a unit quaternion.
pub type Rotation = UnitQuaternion<Real>;

/// A prescribed sinusoidal displacement `amplitude sin(2 pi frequency t)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oscillation {
    /// m, in the world frame.
    pub amplitude: Vector,
    /// Hz.
    pub frequency: Real,
}

/// How a body moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Motion {
    /// Never moves; its boundary samples are indexed once.
    Static,
    /// Follows a prescribed path whatever the fluid does: from its initial
    /// pose, translation at `velocity` plus the oscillation, and rotation
    /// at the constant `angular_velocity` (world frame) about its centre.
    Kinematic {
        /// m/s.
        velocity: Vector,
        /// rad/s, world frame.
        angular_velocity: Vector,
        /// Added to the path.
        oscillation: Option<Oscillation>,
    },
    /// Moved by gravity and the fluid (two-way coupling).
    Dynamic {
        /// kg (per metre of depth in 2D).
        mass: Real,
        /// Principal moments of inertia in the body frame, kg m^2.
        inertia: Vector,
    },
}

/// The tangential condition where the fluid meets the body.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Slip {
    /// No tangential force: the fluid slides along the surface.
    Free,
    /// A viscous wall term with the body's surface velocity (see
    /// [`super::RigidBodies`]); `viscosity` is its dynamic viscosity mu,
    /// Pa s.
    No {
        /// mu, Pa s.
        viscosity: Real,
    },
}

/// The part of a body that moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyState {
    /// Centre (of mass), m.
    pub position: Vector,
    /// Turns the body frame into the world frame.
    pub orientation: Rotation,
    /// Velocity of the centre, m/s.
    pub velocity: Vector,
    /// rad/s, world frame.
    pub angular_velocity: Vector,
    /// Time since the body was built, s (the clock of a kinematic path).
    pub time: Real,
}

/// A rigid body.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidBody {
    /// Its shape in the body frame.
    pub shape: Shape,
    /// How it moves.
    pub motion: Motion,
    /// How the fluid meets its surface.
    pub slip: Slip,
    /// The fluid fills the inside of the shape (a container) instead of
    /// surrounding it.
    pub hollow: bool,
    /// Index of the body's system in the scene.
    pub system: usize,
    /// 2 or 3; in 2D the body moves in the plane z = 0 and turns about z.
    pub dim: usize,
    /// Where it is and how it moves now.
    pub state: BodyState,
    /// The state it was built with: the origin of a kinematic path.
    initial: BodyState,
}

impl RigidBody {
    /// A body in `state`, which is also the origin of a kinematic path.
    pub fn new(
        shape: Shape,
        motion: Motion,
        slip: Slip,
        hollow: bool,
        system: usize,
        dim: usize,
        state: BodyState,
    ) -> Self {
        let mut body = Self {
            shape,
            motion,
            slip,
            hollow,
            system,
            dim,
            state,
            initial: state,
        };
        body.follow_path(0.0);
        body
    }

    /// Whether the body can move at all.
    pub fn moves(&self) -> bool {
        !matches!(self.motion, Motion::Static)
    }

    /// Body-frame coordinates of a world point.
    #[inline]
    pub fn to_local(&self, x: &Vector) -> Vector {
        self.state
            .orientation
            .inverse_transform_vector(&(x - self.state.position))
    }

    /// Signed distance of a world point from the region the fluid may not
    /// enter (the solid, or for a hollow body everything outside it):
    /// negative in there.
    #[inline]
    pub fn excluded_distance(&self, x: &Vector) -> Real {
        let d = self.shape.signed_distance(&self.to_local(x), self.dim);
        if self.hollow { -d } else { d }
    }

    /// Unit normal at a world point pointing from the excluded region into
    /// the fluid.
    #[inline]
    pub fn fluid_normal(&self, x: &Vector) -> Vector {
        let n = self
            .state
            .orientation
            .transform_vector(&self.shape.normal(&self.to_local(x), self.dim));
        if self.hollow { -n } else { n }
    }

    /// Velocity of the body's material at world point `x`.
    #[inline]
    pub fn point_velocity(&self, x: &Vector) -> Vector {
        self.state.velocity
            + self
                .state
                .angular_velocity
                .cross(&(x - self.state.position))
    }

    /// World-frame inverse inertia `R I_body^-1 R^T`; in 2D only the z
    /// moment acts. Zero for bodies that are not dynamic.
    pub fn inverse_inertia(&self) -> Matrix3<Real> {
        let Motion::Dynamic { inertia, .. } = self.motion else {
            return Matrix3::zeros();
        };
        if self.dim == 2 {
            return Matrix3::from_diagonal(&Vector::new(0.0, 0.0, 1.0 / inertia.z));
        }
        let r = self.state.orientation.to_rotation_matrix().into_inner();
        r * Matrix3::from_diagonal(&inertia.map(|i| 1.0 / i)) * r.transpose()
    }

    fn inverse_mass(&self) -> Real {
        match self.motion {
            Motion::Dynamic { mass, .. } => 1.0 / mass,
            _ => 0.0,
        }
    }

    /// Sets a kinematic body to its prescribed pose and velocity at time
    /// `t`: no drift, whatever the sub-steps.
    fn follow_path(&mut self, t: Real) {
        let Motion::Kinematic {
            velocity,
            angular_velocity,
            oscillation,
        } = self.motion
        else {
            return;
        };
        let (offset, wobble) = oscillation.map_or((Vector::zeros(), Vector::zeros()), |o| {
            let phase = 2.0 * PI * o.frequency * t;
            (
                o.amplitude * phase.sin(),
                o.amplitude * (2.0 * PI * o.frequency * phase.cos()),
            )
        });
        self.state.position = self.initial.position + velocity * t + offset;
        self.state.velocity = velocity + wobble;
        self.state.orientation =
            Rotation::from_scaled_axis(angular_velocity * t) * self.initial.orientation;
        self.state.angular_velocity = angular_velocity;
        self.state.time = t;
    }

    /// Advances the body by `dt` under the fluid's `force` and `torque`
    /// (about its centre) and gravity: a dynamic body by symplectic Euler,
    /// a kinematic one along its path; a static one stays.
    pub fn advance(&mut self, dt: Real, force: &Vector, torque: &Vector, gravity: &Vector) {
        match self.motion {
            Motion::Static => self.state.time += dt,
            Motion::Kinematic { .. } => self.follow_path(self.state.time + dt),
            Motion::Dynamic { mass, inertia } => {
                let planar = self.dim == 2;
                let s = &mut self.state;
                s.velocity += (force / mass + gravity) * dt;
                if planar {
                    s.velocity.z = 0.0;
                    s.angular_velocity.z += torque.z / inertia.z * dt;
                } else {
                    let r = s.orientation.to_rotation_matrix().into_inner();
                    let inertia_world = r * Matrix3::from_diagonal(&inertia) * r.transpose();
                    let inverse =
                        r * Matrix3::from_diagonal(&inertia.map(|i| 1.0 / i)) * r.transpose();
                    let w = s.angular_velocity;
                    s.angular_velocity += inverse * (torque - w.cross(&(inertia_world * w))) * dt;
                }
                s.position += s.velocity * dt;
                let turn = Rotation::from_scaled_axis(s.angular_velocity * dt);
                s.orientation = Rotation::new_normalize((turn * s.orientation).into_inner());
                s.time += dt;
            }
        }
    }

    /// Changes a dynamic body's velocities by a linear `impulse` and an
    /// angular one (about its centre); others ignore it.
    pub fn apply_impulse(&mut self, impulse: &Vector, angular: &Vector) {
        let inverse_mass = self.inverse_mass();
        if inverse_mass == 0.0 {
            return;
        }
        let mut dv = impulse * inverse_mass;
        if self.dim == 2 {
            dv.z = 0.0;
        }
        self.state.velocity += dv;
        self.state.angular_velocity += self.inverse_inertia() * angular;
    }

    /// Keeps a dynamic body inside the box `[min, max]`, given its surface
    /// samples in world coordinates. For each wall that samples crossed,
    /// the body is moved back by the deepest crossing, and an inelastic,
    /// frictionless impulse at the centroid of the crossing samples stops
    /// the approach of that point along the wall's normal:
    /// `j = -u_n / (1/M + ((I^-1 (r x n)) x r) . n)`, the textbook impulse
    /// of a rigid body against a fixed plane with restitution 0. Using the
    /// centroid makes a face resting flat on a wall feel no torque.
    pub fn contain(&mut self, samples: &[Vector], min: &Vector, max: &Vector) {
        if !matches!(self.motion, Motion::Dynamic { .. }) {
            return;
        }
        for axis in 0..self.dim {
            for side in [-1.0, 1.0] {
                // Inward normal of the wall.
                let mut n = Vector::zeros();
                n[axis] = -side;
                let wall = if side < 0.0 { min[axis] } else { max[axis] };
                let (mut depth, mut centroid, mut count) = (0.0 as Real, Vector::zeros(), 0);
                for x in samples {
                    let beyond = (x[axis] - wall) * side;
                    if beyond > 0.0 {
                        depth = depth.max(beyond);
                        centroid += x;
                        count += 1;
                    }
                }
                if count == 0 {
                    continue;
                }
                let contact = centroid / count as Real + n * depth;
                self.state.position += n * depth;
                let r = contact - self.state.position;
                let approach = self.point_velocity(&contact).dot(&n);
                if approach < 0.0 {
                    let rn = r.cross(&n);
                    let k = self.inverse_mass() + (self.inverse_inertia() * rn).cross(&r).dot(&n);
                    let j = -approach / k;
                    self.apply_impulse(&(n * j), &(rn * j));
                }
            }
        }
    }

    /// The largest speed of any point of the body within `reach` of its
    /// centre.
    pub fn max_speed(&self, reach: Real) -> Real {
        self.state.velocity.norm() + self.state.angular_velocity.norm() * reach
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ball(motion: Motion, dim: usize) -> RigidBody {
        RigidBody::new(
            Shape::Sphere { radius: 0.1 },
            motion,
            Slip::Free,
            false,
            0,
            dim,
            BodyState {
                position: Vector::new(0.5, 0.5, 0.5),
                orientation: Rotation::identity(),
                velocity: Vector::zeros(),
                angular_velocity: Vector::zeros(),
                time: 0.0,
            },
        )
    }

    /// Free fall: symplectic Euler gives `x = x0 - g t^2 / 2 - g dt t / 2`
    /// after `n` steps (exact for the scheme); the error against the
    /// continuous parabola is then `g dt t / 2`.
    #[test]
    fn a_dynamic_body_falls_under_gravity() {
        let mut body = ball(
            Motion::Dynamic {
                mass: 1.0,
                inertia: Vector::repeat(0.004),
            },
            3,
        );
        let (dt, g) = (1e-3, Vector::new(0.0, -9.81, 0.0));
        for _ in 0..100 {
            body.advance(dt, &Vector::zeros(), &Vector::zeros(), &g);
        }
        let t: Real = 0.1;
        let expected = 0.5 - 0.5 * 9.81 * t * t - 0.5 * 9.81 * dt * t;
        assert!((body.state.position.y - expected).abs() < 1e-12);
        assert!((body.state.velocity.y + 9.81 * t).abs() < 1e-12);
    }

    /// A torque-free box spinning about a principal axis keeps spinning at
    /// the same rate, with a unit quaternion; a constant torque about a
    /// principal axis spins it up at `tau / I`.
    #[test]
    fn rotation_follows_euler_equations() {
        let inertia = Vector::new(0.01, 0.02, 0.03);
        let mut body = ball(Motion::Dynamic { mass: 1.0, inertia }, 3);
        body.state.angular_velocity = Vector::new(0.0, 0.0, 2.0);
        for _ in 0..1000 {
            body.advance(1e-3, &Vector::zeros(), &Vector::zeros(), &Vector::zeros());
        }
        assert!((body.state.angular_velocity - Vector::new(0.0, 0.0, 2.0)).norm() < 1e-9);
        let angle = body.state.orientation.angle();
        assert!(
            (angle - 2.0).abs() < 1e-9,
            "turned {angle} rad in 1 s at 2 rad/s"
        );
        assert!((body.state.orientation.into_inner().norm() - 1.0).abs() < 1e-12);

        body.state.angular_velocity = Vector::zeros();
        body.state.orientation = Rotation::identity();
        for _ in 0..100 {
            body.advance(
                1e-3,
                &Vector::zeros(),
                &Vector::new(0.0, 0.06, 0.0),
                &Vector::zeros(),
            );
        }
        assert!((body.state.angular_velocity.y - 0.3).abs() < 1e-9);
    }

    /// A kinematic oscillation follows `x0 + A sin(2 pi f t)` exactly, and
    /// reports the derivative as its velocity.
    #[test]
    fn a_kinematic_body_follows_its_path() {
        let amplitude = Vector::new(0.05, 0.0, 0.0);
        let mut body = ball(
            Motion::Kinematic {
                velocity: Vector::zeros(),
                angular_velocity: Vector::new(0.0, 0.0, 1.0),
                oscillation: Some(Oscillation {
                    amplitude,
                    frequency: 2.0,
                }),
            },
            2,
        );
        assert!((body.state.velocity.x - 0.05 * 4.0 * PI).abs() < 1e-12);
        for _ in 0..30 {
            body.advance(
                0.01,
                &Vector::new(1e3, 0.0, 0.0),
                &Vector::zeros(),
                &Vector::zeros(),
            );
        }
        let t: Real = 0.3;
        let x = 0.5 + 0.05 * (4.0 * PI * t).sin();
        assert!((body.state.position.x - x).abs() < 1e-12);
        assert!((body.state.orientation.angle() - 0.3).abs() < 1e-12);
    }

    /// A body pressed into the floor is lifted back onto it and loses its
    /// downward speed; a face resting flat gains no spin.
    #[test]
    fn contact_keeps_a_body_in_the_box() {
        let mut body = RigidBody::new(
            Shape::Box {
                half_extents: Vector::new(0.1, 0.05, 0.1),
            },
            Motion::Dynamic {
                mass: 1.0,
                inertia: Vector::repeat(0.01),
            },
            Slip::Free,
            false,
            0,
            3,
            BodyState {
                position: Vector::new(0.5, 0.04, 0.5),
                orientation: Rotation::identity(),
                velocity: Vector::new(0.2, -1.0, 0.0),
                angular_velocity: Vector::zeros(),
                time: 0.0,
            },
        );
        let local = body.shape.sample_surface(0.02, 3, &Vector::zeros(), 0.0);
        let world: Vec<Vector> = local.iter().map(|p| p + body.state.position).collect();
        body.contain(&world, &Vector::zeros(), &Vector::repeat(1.0));
        assert!((body.state.position.y - 0.05).abs() < 1e-12);
        assert!(body.state.velocity.y.abs() < 1e-12);
        assert!((body.state.velocity.x - 0.2).abs() < 1e-12, "frictionless");
        assert!(body.state.angular_velocity.norm() < 1e-12);
    }
}
