//! Conversions of the rigid body's messages (`RigidBodySpec`), both
//! directions, and the tables of its motion and slip condition.

use super::geometry::{shape_from_proto, to_shape, to_vec3, vec3};
use crate::enums::{WireEnum, enum_or, wire_enum};
use crate::error::WireError;
use crate::error::{Result, required};
use meshless_engine::scene::{MotionKind, OscillationSpec, RigidBodySpec, SlipKind, defaults};
use meshless_proto::v1;

wire_enum! {
    /// How a rigid body moves.
    MotionKind <-> RigidMotion, "motion" {
        "static" => Static,
        "kinematic" => Kinematic,
        "dynamic" => Dynamic,
    }
}

wire_enum! {
    /// The tangential condition where the fluid meets a body.
    SlipKind <-> SlipCondition, "slip condition" {
        "free" => Free,
        "no" => No,
    }
}

/// The engine body of a `RigidBodySpec`.
pub(super) fn body_from_proto(body: v1::RigidBodySpec, field: &str) -> Result<RigidBodySpec> {
    let v1::RigidBodySpec {
        shape,
        position,
        orientation,
        motion,
        density,
        velocity,
        angular_velocity,
        oscillation,
        slip,
        viscosity,
        hollow,
    } = body;
    let oscillation = oscillation
        .map(|o| {
            let v1::Oscillation {
                amplitude,
                frequency,
            } = o;
            Ok::<_, WireError>(OscillationSpec {
                amplitude: vec3(required(
                    amplitude,
                    &format!("{field}.oscillation.amplitude"),
                )?),
                frequency,
            })
        })
        .transpose()?;
    Ok(RigidBodySpec {
        shape: shape_from_proto(shape, &format!("{field}.shape"))?,
        position: vec3(required(position, &format!("{field}.position"))?),
        orientation: orientation.map_or([0.0; 3], vec3),
        motion: enum_or(motion, defaults::MOTION, &format!("{field}.motion"))?,
        density,
        velocity: velocity.map_or([0.0; 3], vec3),
        angular_velocity: angular_velocity.map_or([0.0; 3], vec3),
        oscillation,
        slip: enum_or(slip, defaults::SLIP, &format!("{field}.slip"))?,
        viscosity,
        hollow,
    })
}

/// The wire form of a rigid body.
pub(super) fn to_body(b: &RigidBodySpec) -> v1::RigidBodySpec {
    v1::RigidBodySpec {
        shape: Some(to_shape(&b.shape)),
        position: Some(to_vec3(b.position)),
        orientation: Some(to_vec3(b.orientation)),
        motion: b.motion.to_i32(),
        density: b.density,
        velocity: Some(to_vec3(b.velocity)),
        angular_velocity: Some(to_vec3(b.angular_velocity)),
        oscillation: b.oscillation.map(|o| v1::Oscillation {
            amplitude: Some(to_vec3(o.amplitude)),
            frequency: o.frequency,
        }),
        slip: b.slip.to_i32(),
        viscosity: b.viscosity,
        hollow: b.hollow,
    }
}
