//! Vectors, boxes and shapes as every system kind's messages carry them,
//! both directions, and the mesh-format table. A leaf of the scene
//! conversions: the kind files import it, it imports none of them.

use crate::enums::{WireEnum, required_enum, wire_enum};
use crate::error::WireError;
use crate::error::{Result, required};
use meshless_engine::geometry::read::MeshFormat;
use meshless_engine::scene::MeshData;
use meshless_engine::scene::{Aabb, ShapeSpec};
use meshless_proto::v1;

wire_enum! {
    /// The format of a mesh file.
    MeshFormat <-> MeshFormat, "mesh format" {
        "obj" => Obj,
        "ply" => Ply,
    }
}

/// The engine form of a vector.
pub(crate) fn vec3(v: v1::Vec3) -> [f64; 3] {
    let v1::Vec3 { x, y, z } = v;
    [x, y, z]
}

/// The wire form of a vector.
pub(crate) fn to_vec3(v: [f64; 3]) -> v1::Vec3 {
    v1::Vec3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

/// The engine box of a required `Aabb` field.
pub(crate) fn aabb(b: Option<v1::Aabb>, field: &str) -> Result<Aabb> {
    let v1::Aabb { min, max } = required(b, field)?;
    Ok(Aabb {
        min: vec3(required(min, &format!("{field}.min"))?),
        max: vec3(required(max, &format!("{field}.max"))?),
    })
}

/// The wire form of a box.
pub(crate) fn to_aabb(b: &Aabb) -> v1::Aabb {
    v1::Aabb {
        min: Some(to_vec3(b.min)),
        max: Some(to_vec3(b.max)),
    }
}

/// The engine shape of a required `Shape` field.
pub(crate) fn shape_from_proto(shape: Option<v1::Shape>, field: &str) -> Result<ShapeSpec> {
    let v1::Shape { kind } = required(shape, field)?;
    match kind {
        Some(v1::shape::Kind::Box(v1::BoxShape { half_extents })) => Ok(ShapeSpec::Box {
            half_extents: vec3(required(half_extents, &format!("{field}.half_extents"))?),
        }),
        Some(v1::shape::Kind::Sphere(v1::SphereShape { radius })) => {
            Ok(ShapeSpec::Sphere { radius })
        }
        Some(v1::shape::Kind::Capsule(v1::CapsuleShape {
            half_length,
            radius,
        })) => Ok(ShapeSpec::Capsule {
            half_length,
            radius,
        }),
        Some(v1::shape::Kind::Plane(v1::PlaneShape { normal, offset })) => Ok(ShapeSpec::Plane {
            normal: vec3(required(normal, &format!("{field}.normal"))?),
            offset,
        }),
        Some(v1::shape::Kind::Mesh(v1::MeshShape { path, scale, data })) => {
            let data = data
                .map(
                    |v1::MeshData {
                         format,
                         content,
                         length: _,
                     }| {
                        Ok::<_, WireError>(MeshData {
                            format: required_enum(format, &format!("{field}.data.format"))?,
                            content,
                        })
                    },
                )
                .transpose()?;
            Ok(ShapeSpec::Mesh {
                path: (!path.is_empty()).then_some(path),
                data,
                scale,
            })
        }
        None => Err(WireError::new(
            format!("{field}.kind"),
            "unknown or missing shape; use box, sphere, capsule, plane or mesh",
        )),
    }
}

/// The wire form of a shape.
pub(crate) fn to_shape(shape: &ShapeSpec) -> v1::Shape {
    let kind = match shape {
        ShapeSpec::Box { half_extents } => v1::shape::Kind::Box(v1::BoxShape {
            half_extents: Some(to_vec3(*half_extents)),
        }),
        ShapeSpec::Sphere { radius } => {
            v1::shape::Kind::Sphere(v1::SphereShape { radius: *radius })
        }
        ShapeSpec::Capsule {
            half_length,
            radius,
        } => v1::shape::Kind::Capsule(v1::CapsuleShape {
            half_length: *half_length,
            radius: *radius,
        }),
        ShapeSpec::Plane { normal, offset } => v1::shape::Kind::Plane(v1::PlaneShape {
            normal: Some(to_vec3(*normal)),
            offset: *offset,
        }),
        ShapeSpec::Mesh { path, data, scale } => v1::shape::Kind::Mesh(v1::MeshShape {
            path: path.clone().unwrap_or_default(),
            scale: *scale,
            data: data.as_ref().map(|d| v1::MeshData {
                format: d.format.to_i32(),
                content: d.content.clone(),
                length: 0,
            }),
        }),
    };
    v1::Shape { kind: Some(kind) }
}
