//! Helpers shared by the rigid-body test files.

use meshless_engine::World;
use meshless_engine::rigid::RigidBody;

/// The first rigid body of a world that has one.
pub fn body(world: &World) -> &RigidBody {
    &world
        .fluid()
        .expect("fluid")
        .bodies()
        .expect("bodies")
        .bodies()[0]
}

/// The fastest fluid particle's speed, m/s.
pub fn max_speed(world: &World) -> f64 {
    let fluid = world.fluid().expect("fluid");
    fluid
        .velocities
        .iter()
        .map(|v| v.norm())
        .fold(0.0, f64::max)
}

/// Fluid particles inside the first body (the fluid side of its surface
/// is positive).
pub fn particles_inside(world: &World) -> usize {
    let b = body(world);
    let fluid = world.fluid().expect("fluid");
    fluid
        .positions
        .iter()
        .filter(|x| b.excluded_distance(x) < 0.0)
        .count()
}
