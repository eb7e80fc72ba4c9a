//! Conversions of the frame messages (`frame.proto`): an engine frame on
//! the wire, each real field as packed little-endian f32 and the particle
//! ids as packed little-endian u32 (right after the positions), and back, for
//! programs that write wire frames with the engine's exporters (`meshless
//! demo`). The way back checks every length, so a malformed frame is an
//! error naming its field rather than a short or shifted one.

use crate::enums::{WireEnum, required_enum};
use crate::error::WireError;
use crate::error::{Result, required};
use crate::scene::{to_vec3, vec3};
use meshless_engine::geometry::TriMesh;
use meshless_engine::math::Vector;
use meshless_engine::{BodyPose, FieldData, FieldKind, Frame, SolidRange, SolidSurface};
use meshless_proto::v1;

/// A frame on the wire: each real field as packed little-endian f32, the
/// ids (when the frame has them) as packed little-endian u32 right after
/// the positions, where the engine's field list names them.
pub fn frame_to_proto(session_id: &str, frame: &Frame) -> v1::Frame {
    let mut fields: Vec<v1::FieldData> = frame
        .fields
        .iter()
        .map(|f| v1::FieldData {
            kind: f.kind.to_i32(),
            components: f.components as u32,
            scalar: v1::ScalarType::F32 as i32,
            data: f.values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        })
        .collect();
    if let Some(ids) = &frame.ids {
        let at = usize::from(frame.fields.first().map(|f| f.kind) == Some(FieldKind::Position));
        fields.insert(
            at,
            v1::FieldData {
                kind: FieldKind::Id.to_i32(),
                components: 1,
                scalar: v1::ScalarType::U32 as i32,
                data: ids.iter().flat_map(|id| id.to_le_bytes()).collect(),
            },
        );
    }
    v1::Frame {
        header: Some(v1::FrameHeader {
            session_id: session_id.to_owned(),
            step: frame.step,
            time: frame.time,
            particle_count: frame.particle_count as u64,
            substeps: frame.substeps,
            substep_dt: frame.substep_dt,
            solver_iterations: frame.solver_iterations,
            density_error: frame.density_error,
            capped: frame.capped,
            unconverged: frame.unconverged,
            added: frame.added,
            fields: fields.iter().map(|f| f.kind).collect(),
        }),
        fields,
        bodies: frame
            .bodies
            .iter()
            .map(|b| {
                let [x, y, z, w] = b.orientation;
                v1::BodyPose {
                    system: b.system as u32,
                    position: Some(to_vec3(b.position)),
                    orientation: Some(v1::Quaternion { x, y, z, w }),
                    velocity: Some(to_vec3(b.velocity)),
                    angular_velocity: Some(to_vec3(b.angular_velocity)),
                }
            })
            .collect(),
        surface: frame
            .surface
            .as_ref()
            .map(|mesh| to_surface_mesh(mesh, &[])),
        solids: frame.solids.iter().map(to_solid_range).collect(),
        solid_surfaces: frame.solid_surfaces.iter().map(to_solid_surface).collect(),
        crack_surfaces: frame.crack_surfaces.iter().map(to_solid_surface).collect(),
    }
}

/// Packed little-endian f32 vectors, three per entry: how the protocol
/// carries points (frames' meshes, a session's rest positions).
pub fn pack_vectors(vectors: &[Vector]) -> Vec<u8> {
    vectors
        .iter()
        .flat_map(|v| v.iter().flat_map(|&c| (c as f32).to_le_bytes()))
        .collect()
}

/// A mesh on the wire; `normals` empty sends none (the fluid's surface).
fn to_surface_mesh(mesh: &TriMesh, normals: &[Vector]) -> v1::SurfaceMesh {
    v1::SurfaceMesh {
        vertices: pack_vectors(&mesh.vertices),
        triangles: mesh
            .triangles
            .iter()
            .flat_map(|t| t.iter().flat_map(|i| i.to_le_bytes()))
            .collect(),
        normals: pack_vectors(normals),
    }
}

fn to_solid_surface(surface: &SolidSurface) -> v1::SolidSurface {
    let SolidSurface {
        system,
        mesh,
        normals,
    } = surface;
    v1::SolidSurface {
        system: *system as u32,
        mesh: Some(to_surface_mesh(mesh, normals)),
    }
}

fn to_solid_range(range: &SolidRange) -> v1::SolidRange {
    let SolidRange {
        system,
        first,
        count,
    } = *range;
    v1::SolidRange {
        system: system as u32,
        first: first as u64,
        count: count as u64,
    }
}

/// The engine frame of a wire frame, the reverse of [`frame_to_proto`]:
/// the same fields in the same order, vectors widened from f32 to f64.
/// The header's session id and field list are not part of an engine frame.
///
/// # Errors
/// A [`WireError`] naming the field: a missing header, pose or solid
/// mesh; an unknown field kind or scalar type; a field whose size does not
/// match the particle count; a solid's range past the last particle; a
/// mesh whose byte counts are not whole vertices, normals or triangles,
/// whose triangle names a vertex that does not exist, or a solid's mesh
/// without one normal per vertex.
pub fn frame_from_proto(frame: v1::Frame) -> Result<Frame> {
    let v1::Frame {
        header,
        fields,
        bodies,
        surface,
        solids,
        solid_surfaces,
        crack_surfaces,
    } = frame;
    let v1::FrameHeader {
        session_id: _,
        step,
        time,
        particle_count,
        substeps,
        substep_dt,
        fields: _,
        solver_iterations,
        density_error,
        capped,
        unconverged,
        added,
    } = required(header, "header")?;
    let particle_count = usize::try_from(particle_count).map_err(|_| {
        WireError::new(
            "header.particle_count",
            format!("{particle_count} particles do not fit this machine's memory"),
        )
    })?;
    let mut real = Vec::with_capacity(fields.len());
    let mut ids = None;
    for (i, field) in fields.into_iter().enumerate() {
        let path = format!("fields[{i}]");
        match field_from_proto(field, particle_count, &path)? {
            Unpacked::Real(field) => real.push(field),
            Unpacked::Ids(values) if ids.is_none() => ids = Some(values),
            Unpacked::Ids(_) => {
                return Err(WireError::new(
                    format!("{path}.kind"),
                    "a second id field; a frame carries its ids once",
                ));
            }
        }
    }
    let bodies = bodies
        .into_iter()
        .enumerate()
        .map(|(i, pose)| pose_from_proto(pose, &format!("bodies[{i}]")))
        .collect::<Result<_>>()?;
    let surface = surface
        .map(|mesh| mesh_from_proto(mesh, "surface"))
        .transpose()?
        .map(|(mesh, _normals)| mesh);
    let solids = solids
        .into_iter()
        .enumerate()
        .map(|(i, range)| range_from_proto(range, particle_count, &format!("solids[{i}]")))
        .collect::<Result<_>>()?;
    let solid_surfaces = solid_surfaces
        .into_iter()
        .enumerate()
        .map(|(i, surface)| solid_surface_from_proto(surface, &format!("solid_surfaces[{i}]")))
        .collect::<Result<_>>()?;
    let crack_surfaces = crack_surfaces
        .into_iter()
        .enumerate()
        .map(|(i, surface)| solid_surface_from_proto(surface, &format!("crack_surfaces[{i}]")))
        .collect::<Result<_>>()?;
    Ok(Frame {
        step,
        time,
        substeps,
        substep_dt,
        solver_iterations,
        density_error,
        capped,
        unconverged,
        added,
        particle_count,
        fields: real,
        ids,
        bodies,
        surface,
        solids,
        solid_surfaces,
        crack_surfaces,
    })
}

/// A wire field unpacked: real values, or the particles' ids.
enum Unpacked {
    Real(FieldData),
    Ids(Vec<u32>),
}

/// A field of `particles` particles, its packed values unpacked: f32 for
/// every kind but [`FieldKind::Id`], u32 for the ids.
fn field_from_proto(field: v1::FieldData, particles: usize, path: &str) -> Result<Unpacked> {
    let v1::FieldData {
        kind,
        components,
        scalar,
        data,
    } = field;
    let kind = required_enum::<FieldKind>(kind, &format!("{path}.kind"))?;
    let (expected_scalar, name) = if kind.is_integer() {
        (v1::ScalarType::U32, "u32")
    } else {
        (v1::ScalarType::F32, "f32")
    };
    if scalar != expected_scalar as i32 {
        return Err(WireError::new(
            format!("{path}.scalar"),
            format!(
                "scalar type {scalar}; a {} field is {name} ({})",
                kind.name(),
                expected_scalar as i32
            ),
        ));
    }
    let components = components as usize;
    if components != kind.components() {
        return Err(WireError::new(
            format!("{path}.components"),
            format!(
                "is {components}; a {} field has {}",
                kind.name(),
                kind.components()
            ),
        ));
    }
    // Checked: a header may claim any particle count, and 4 x components
    // x a count near 2^62 wraps around to a small length (to 0 for an
    // empty field), which would pass a field too short for its count.
    let expected = particles
        .checked_mul(4 * components)
        .filter(|&bytes| bytes == data.len());
    if expected.is_none() {
        return Err(WireError::new(
            format!("{path}.data"),
            format!(
                "has {} bytes, expected 4 x {components} components x {particles} particles",
                data.len()
            ),
        ));
    }
    let words = data.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]);
    Ok(if kind.is_integer() {
        Unpacked::Ids(words.map(u32::from_le_bytes).collect())
    } else {
        Unpacked::Real(FieldData {
            kind,
            components,
            values: words.map(f32::from_le_bytes).collect(),
        })
    })
}

fn pose_from_proto(pose: v1::BodyPose, path: &str) -> Result<BodyPose> {
    let v1::BodyPose {
        system,
        position,
        orientation,
        velocity,
        angular_velocity,
    } = pose;
    let v1::Quaternion { x, y, z, w } = required(orientation, &format!("{path}.orientation"))?;
    Ok(BodyPose {
        system: system as usize,
        position: vec3(required(position, &format!("{path}.position"))?),
        orientation: [x, y, z, w],
        velocity: vec3(required(velocity, &format!("{path}.velocity"))?),
        angular_velocity: vec3(required(
            angular_velocity,
            &format!("{path}.angular_velocity"),
        )?),
    })
}

/// Packed little-endian f32 triples as engine vectors.
fn unpack_vectors(bytes: &[u8]) -> Vec<Vector> {
    bytes
        .chunks_exact(12)
        .map(|c| {
            let at = |o: usize| f64::from(f32::from_le_bytes([c[o], c[o + 1], c[o + 2], c[o + 3]]));
            Vector::new(at(0), at(4), at(8))
        })
        .collect()
}

/// A mesh and its normals (none for the fluid's surface).
fn mesh_from_proto(mesh: v1::SurfaceMesh, path: &str) -> Result<(TriMesh, Vec<Vector>)> {
    let v1::SurfaceMesh {
        vertices,
        triangles,
        normals,
    } = mesh;
    for (name, bytes) in [
        ("vertices", &vertices),
        ("triangles", &triangles),
        ("normals", &normals),
    ] {
        if bytes.len() % 12 != 0 {
            return Err(WireError::new(
                format!("{path}.{name}"),
                format!(
                    "has {} bytes; it must be a multiple of 12 (three 4-byte numbers each)",
                    bytes.len()
                ),
            ));
        }
    }
    if !normals.is_empty() && normals.len() != vertices.len() {
        return Err(WireError::new(
            format!("{path}.normals"),
            format!(
                "{} normals for {} vertices; give one per vertex or none",
                normals.len() / 12,
                vertices.len() / 12
            ),
        ));
    }
    let vertices = unpack_vectors(&vertices);
    let triangles: Vec<[u32; 3]> = triangles
        .chunks_exact(12)
        .map(|c| [0, 4, 8].map(|o| u32::from_le_bytes([c[o], c[o + 1], c[o + 2], c[o + 3]])))
        .collect();
    if let Some(t) = triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= vertices.len()))
    {
        return Err(WireError::new(
            format!("{path}.triangles"),
            format!(
                "triangle {t} is {:?}, but there are {} vertices",
                triangles[t],
                vertices.len()
            ),
        ));
    }
    Ok((
        TriMesh {
            vertices,
            triangles,
        },
        unpack_vectors(&normals),
    ))
}

fn range_from_proto(range: v1::SolidRange, particles: usize, path: &str) -> Result<SolidRange> {
    let v1::SolidRange {
        system,
        first,
        count,
    } = range;
    if first
        .checked_add(count)
        .is_none_or(|end| end > particles as u64)
    {
        return Err(WireError::new(
            path,
            format!("holds particles {first}..+{count}, past the frame's {particles}"),
        ));
    }
    Ok(SolidRange {
        system: system as usize,
        first: first as usize,
        count: count as usize,
    })
}

fn solid_surface_from_proto(surface: v1::SolidSurface, path: &str) -> Result<SolidSurface> {
    let v1::SolidSurface { system, mesh } = surface;
    let path = format!("{path}.mesh");
    let (mesh, normals) = mesh_from_proto(required(mesh, &path)?, &path)?;
    if normals.len() != mesh.vertices.len() {
        return Err(WireError::new(
            format!("{path}.normals"),
            format!(
                "{} normals for {} vertices; a solid's surface needs one per vertex",
                normals.len(),
                mesh.vertices.len()
            ),
        ));
    }
    Ok(SolidSurface {
        system: system as usize,
        mesh,
        normals,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::scene::SolidSurfaceSpec;
    use meshless_engine::scene::SystemSpec;
    use meshless_engine::solid::embedded::EmbeddingMethod;
    use meshless_engine::{BuildOptions, Scene};

    fn dam_break() -> Scene {
        Scene::from_toml_str(include_str!("../../scenes/dam_break.toml")).expect("shipped scene")
    }

    #[test]
    fn frames_pack_fields_little_endian() {
        let world = dam_break().build(&BuildOptions::default()).expect("world");
        let frame = world.frame();
        let wire = frame_to_proto("s", &frame);
        let positions = &wire.fields[0];
        assert_eq!(positions.data.len(), 4 * 3 * frame.particle_count);
        let x0 = f32::from_le_bytes(positions.data[0..4].try_into().expect("4 bytes"));
        assert_eq!(x0, frame.fields[0].values[0]);
        assert_eq!(wire.header.expect("header").fields.len(), wire.fields.len());
        assert_eq!(wire.surface, None, "no surface unless the scene asks");
        assert!(wire.solid_surfaces.is_empty());
    }

    /// A vector as the wire carries it: each coordinate rounded to f32.
    fn rounded(v: &Vector) -> Vector {
        v.map(|c| f64::from(c as f32))
    }

    /// engine -> proto -> engine gives the frame back, its vectors rounded
    /// to f32 and its values exactly: fields, poses, the fluid's surface,
    /// solid ranges and solid surfaces with their normals.
    #[test]
    fn frames_round_trip_through_the_protocol() {
        let mut scene = Scene::from_toml_str(include_str!("../../scenes/floating_box.toml"))
            .expect("shipped scene");
        scene.output.surface = Some(meshless_engine::scene::SurfaceSpec {
            cell: None,
            iso: 0.5,
        });
        let mut jelly = Scene::from_toml_str(include_str!("../../scenes/jelly_drop.toml"))
            .expect("shipped scene");
        let SystemSpec::Solid(solid) = &mut jelly.systems[0] else {
            panic!("the jelly is a solid")
        };
        solid.surface = Some(SolidSurfaceSpec {
            method: EmbeddingMethod::ShapeFunctions,
            subdivisions: 1,
        });
        jelly.output.fields.push(FieldKind::Id);
        for scene in [scene, jelly] {
            let frame = scene
                .build(&BuildOptions::default())
                .expect("valid")
                .frame();
            assert!(
                frame.surface.is_some() || !frame.solid_surfaces.is_empty(),
                "{}: a frame with a surface",
                scene.name
            );
            let back = frame_from_proto(frame_to_proto("s", &frame)).expect("round trip");
            let mut expected = frame.clone();
            if let Some(mesh) = &mut expected.surface {
                mesh.vertices = mesh.vertices.iter().map(rounded).collect();
            }
            for s in &mut expected.solid_surfaces {
                s.mesh.vertices = s.mesh.vertices.iter().map(rounded).collect();
                s.normals = s.normals.iter().map(rounded).collect();
            }
            assert_eq!(back, expected, "{}", scene.name);
        }
    }

    /// Ids travel as u32 right after the positions, and a frame whose ids
    /// are mislabelled or doubled is refused.
    #[test]
    fn ids_follow_the_positions_as_integers() {
        let mut scene = dam_break();
        scene.output.fields.push(FieldKind::Id);
        let frame = scene
            .build(&BuildOptions::default())
            .expect("valid")
            .frame();
        let ids = frame.ids.clone().expect("the scene names ids");
        let wire = frame_to_proto("s", &frame);
        let header = wire.header.as_ref().expect("header");
        assert_eq!(header.fields[1], FieldKind::Id.to_i32());
        assert_eq!(wire.fields[1].scalar, v1::ScalarType::U32 as i32);
        let last = ids.len() - 1;
        let at = 4 * last;
        let bytes = wire.fields[1].data[at..at + 4].try_into().expect("4 bytes");
        assert_eq!(u32::from_le_bytes(bytes), ids[last]);
        let back = frame_from_proto(wire.clone()).expect("round trip");
        assert_eq!(back.ids.as_deref(), Some(ids.as_slice()));
        assert_eq!(back.fields, frame.fields);
        refused(&wire, "fields[1].scalar", |f| {
            f.fields[1].scalar = v1::ScalarType::F32 as i32;
        });
        refused(&wire, "fields[0].scalar", |f| {
            f.fields[0].scalar = v1::ScalarType::U32 as i32;
        });
        refused(&wire, "fields[2].kind", |f| {
            let again = f.fields[1].clone();
            f.fields.insert(2, again);
        });
    }

    /// `frame` with `change` made is refused, naming `path`.
    fn refused(frame: &v1::Frame, path: &str, change: impl Fn(&mut v1::Frame)) {
        let mut bad = frame.clone();
        change(&mut bad);
        let err = frame_from_proto(bad).expect_err(path);
        assert!(err.to_string().starts_with(&format!("{path}:")), "{err}");
    }

    /// A triangle naming vertex 3 of three.
    fn bad_triangle(frame: &mut v1::Frame) {
        frame.surface = Some(v1::SurfaceMesh {
            vertices: [0.0f32; 9].iter().flat_map(|c| c.to_le_bytes()).collect(),
            triangles: [0u32, 1, 3].iter().flat_map(|i| i.to_le_bytes()).collect(),
            normals: Vec::new(),
        });
    }

    /// Inconsistent frames are refused with the path of what is wrong.
    #[test]
    fn inconsistent_frames_name_their_field() {
        let world = dam_break().build(&BuildOptions::default()).expect("valid");
        let frame = frame_to_proto("s", &world.frame());
        refused(&frame, "header", |f| f.header = None);
        refused(&frame, "fields[1].data", |f| {
            let len = f.fields[1].data.len();
            f.fields[1].data.truncate(len - 1);
        });
        refused(&frame, "fields[0].kind", |f| f.fields[0].kind = 0);
        // 4 x 3 x 2^62 bytes wraps to 0: an empty position field for
        // 2^62 particles once overflowed and was accepted (release) or
        // panicked (debug).
        refused(&frame, "fields[0].data", |f| {
            if let Some(header) = &mut f.header {
                header.particle_count = 1 << 62;
            }
            f.fields[0].data.clear();
        });
        refused(&frame, "fields[0].scalar", |f| f.fields[0].scalar = 7);
        refused(&frame, "fields[0].components", |f| {
            f.fields[0].components = 1;
        });
        refused(&frame, "bodies[0].position", |f| {
            f.bodies = vec![v1::BodyPose {
                orientation: Some(v1::Quaternion::default()),
                ..v1::BodyPose::default()
            }];
        });
        refused(&frame, "solids[0]", |f| {
            f.solids = vec![v1::SolidRange {
                system: 1,
                first: u64::MAX,
                count: 2,
            }];
        });
        refused(&frame, "surface.triangles", bad_triangle);
        refused(&frame, "surface.vertices", |f| {
            bad_triangle(f);
            if let Some(mesh) = &mut f.surface {
                mesh.vertices.pop();
            }
        });
        refused(&frame, "solid_surfaces[0].mesh", |f| {
            f.solid_surfaces = vec![v1::SolidSurface {
                system: 0,
                mesh: None,
            }];
        });
    }
}
