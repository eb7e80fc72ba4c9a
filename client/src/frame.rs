//! Decoded frames: the protocol's packed little-endian fields as `f32`.

use crate::ClientError;
use meshless_proto::v1;
use prost::Message;

/// One particle field.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldView {
    /// The quantity the field holds.
    pub kind: v1::FieldKind,
    /// Scalars per particle (3 for vectors).
    pub components: usize,
    /// `particle_count * components` values, particle-major.
    pub values: Vec<f32>,
}

/// A decoded surface mesh: counter-clockwise triangles facing out of the
/// fluid or solid.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfaceView {
    /// Vertex positions, m.
    pub vertices: Vec<[f32; 3]>,
    /// Each triangle's three indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
    /// Unit normal per vertex; empty for the fluid's surface.
    pub normals: Vec<[f32; 3]>,
}

impl SurfaceView {
    /// Unpacks a surface message.
    ///
    /// # Errors
    /// [`ClientError::Decode`] when a byte count is not whole vertices,
    /// normals or triangles, there are normals but not one per vertex, or
    /// a triangle names a vertex that does not exist.
    pub fn from_proto(surface: v1::SurfaceMesh) -> Result<Self, ClientError> {
        let v1::SurfaceMesh {
            vertices,
            triangles,
            normals,
        } = surface;
        if vertices.len() % 12 != 0 || triangles.len() % 12 != 0 || normals.len() % 12 != 0 {
            return Err(ClientError::Decode(format!(
                "surface has {} vertex bytes, {} triangle bytes and {} normal bytes; \
                 each must be a multiple of 12",
                vertices.len(),
                triangles.len(),
                normals.len()
            )));
        }
        if !normals.is_empty() && normals.len() != vertices.len() {
            return Err(ClientError::Decode(format!(
                "surface has {} normals for {} vertices; it needs one per vertex or none",
                normals.len() / 12,
                vertices.len() / 12
            )));
        }
        let triples = |bytes: &[u8]| -> Vec<[[u8; 4]; 3]> {
            bytes
                .chunks_exact(12)
                .map(|c| [0, 4, 8].map(|o| [c[o], c[o + 1], c[o + 2], c[o + 3]]))
                .collect()
        };
        let floats = |bytes: &[u8]| -> Vec<[f32; 3]> {
            triples(bytes)
                .into_iter()
                .map(|v| v.map(f32::from_le_bytes))
                .collect()
        };
        let vertices = floats(&vertices);
        let normals = floats(&normals);
        let triangles: Vec<[u32; 3]> = triples(&triangles)
            .into_iter()
            .map(|t| t.map(u32::from_le_bytes))
            .collect();
        if let Some(t) = triangles
            .iter()
            .position(|t| t.iter().any(|&i| i as usize >= vertices.len()))
        {
            return Err(ClientError::Decode(format!(
                "surface triangle {t} is {:?}, but there are {} vertices",
                triangles[t],
                vertices.len()
            )));
        }
        Ok(Self {
            vertices,
            triangles,
            normals,
        })
    }
}

/// A solid's embedded surface as deformed in a frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SolidSurfaceView {
    /// Index of the solid's system in the scene.
    pub system: u32,
    /// Carries a unit normal per vertex.
    pub mesh: SurfaceView,
}

impl SolidSurfaceView {
    /// Unpacks a solid surface message.
    ///
    /// # Errors
    /// [`ClientError::Decode`] when the mesh is missing or inconsistent,
    /// or lacks its normals.
    pub fn from_proto(surface: v1::SolidSurface) -> Result<Self, ClientError> {
        let v1::SolidSurface { system, mesh } = surface;
        let mesh = mesh
            .ok_or_else(|| ClientError::Decode(format!("solid {system}'s surface has no mesh")))
            .and_then(SurfaceView::from_proto)
            .map_err(|e| ClientError::Decode(format!("solid {system}: {e}")))?;
        if mesh.normals.len() != mesh.vertices.len() {
            return Err(ClientError::Decode(format!(
                "solid {system}'s surface has {} normals for {} vertices; it needs one per vertex",
                mesh.normals.len(),
                mesh.vertices.len()
            )));
        }
        Ok(Self { system, mesh })
    }
}

/// A decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameView {
    /// The session that published the frame.
    pub session_id: String,
    /// Steps completed since the scene was built or reset.
    pub step: u64,
    /// Simulated time, s.
    pub time: f64,
    /// Particles in every field: the fluid's, then each solid's in scene
    /// order.
    pub particle_count: usize,
    /// Sub-steps the last step was split into: the most any system took.
    pub substeps: u32,
    /// The shortest of those sub-steps, s.
    pub substep_dt: f64,
    /// Pressure-solver iterations of the last step (0 for WCSPH).
    pub solver_iterations: u32,
    /// Worst average density error of the last step's solves (fraction).
    pub density_error: f64,
    /// The particle fields: position first, then the scene's
    /// `output.fields`, each once.
    pub fields: Vec<FieldView>,
    /// Every rigid body's pose, in scene order (empty without bodies).
    pub bodies: Vec<v1::BodyPose>,
    /// The fluid's surface, when the scene's output asks for one.
    pub surface: Option<SurfaceView>,
    /// Where each elastic solid's particles sit in `fields` (after the
    /// fluid's), in scene order; empty without solids.
    pub solids: Vec<v1::SolidRange>,
    /// The deformed surface of every solid that embeds one, in scene
    /// order.
    pub solid_surfaces: Vec<SolidSurfaceView>,
}

impl FrameView {
    /// Decodes an encoded `meshless.v1.Frame`.
    ///
    /// # Errors
    /// [`ClientError::Decode`] when the bytes are not a consistent frame.
    pub fn decode(bytes: &[u8]) -> Result<Self, ClientError> {
        let frame = v1::Frame::decode(bytes).map_err(|e| ClientError::Decode(e.to_string()))?;
        Self::from_proto(frame)
    }

    /// Checks and unpacks a frame message.
    ///
    /// # Errors
    /// [`ClientError::Decode`] for a missing header, an unknown scalar
    /// type, a field whose size does not match the particle count, a
    /// solid's range past the last particle, or an inconsistent surface
    /// (the fluid's or a solid's).
    pub fn from_proto(frame: v1::Frame) -> Result<Self, ClientError> {
        let v1::Frame {
            header,
            fields,
            bodies,
            surface,
            solids,
            solid_surfaces,
        } = frame;
        let v1::FrameHeader {
            session_id,
            step,
            time,
            particle_count,
            substeps,
            substep_dt,
            fields: _,
            solver_iterations,
            density_error,
        } = header.ok_or_else(|| ClientError::Decode("no header".into()))?;
        let particle_count = usize::try_from(particle_count)
            .map_err(|_| ClientError::Decode(format!("particle count {particle_count}")))?;
        let fields = fields
            .into_iter()
            .map(|field| {
                let v1::FieldData {
                    kind,
                    components,
                    scalar,
                    data,
                } = field;
                let kind = v1::FieldKind::try_from(kind)
                    .map_err(|_| ClientError::Decode(format!("unknown field kind {kind}")))?;
                if scalar != v1::ScalarType::F32 as i32 {
                    return Err(ClientError::Decode(format!(
                        "field {kind:?} has scalar type {scalar}, expected f32"
                    )));
                }
                let components = components as usize;
                if data.len() != 4 * components * particle_count {
                    return Err(ClientError::Decode(format!(
                        "field {kind:?} has {} bytes, expected {} for {particle_count} particles x {components}",
                        data.len(),
                        4 * components * particle_count
                    )));
                }
                let values = data
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect();
                Ok(FieldView {
                    kind,
                    components,
                    values,
                })
            })
            .collect::<Result<_, _>>()?;
        if let Some(range) = solids.iter().find(|r| {
            r.first
                .checked_add(r.count)
                .is_none_or(|end| end > particle_count as u64)
        }) {
            return Err(ClientError::Decode(format!(
                "solid of system {} holds particles {}..+{}, past the frame's {particle_count}",
                range.system, range.first, range.count
            )));
        }
        Ok(Self {
            session_id,
            step,
            time,
            particle_count,
            substeps,
            substep_dt,
            solver_iterations,
            density_error,
            fields,
            bodies,
            surface: surface.map(SurfaceView::from_proto).transpose()?,
            solids,
            solid_surfaces: solid_surfaces
                .into_iter()
                .map(SolidSurfaceView::from_proto)
                .collect::<Result<_, _>>()?,
        })
    }

    /// The field of a kind, if the frame carries it.
    pub fn field(&self, kind: v1::FieldKind) -> Option<&FieldView> {
        self.fields.iter().find(|f| f.kind == kind)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wire(particles: u64, bytes: usize) -> v1::Frame {
        v1::Frame {
            header: Some(v1::FrameHeader {
                session_id: "s".into(),
                step: 3,
                time: 0.25,
                particle_count: particles,
                substeps: 1,
                substep_dt: 0.25,
                fields: vec![v1::FieldKind::Density as i32],
                solver_iterations: 0,
                density_error: 0.0,
            }),
            fields: vec![v1::FieldData {
                kind: v1::FieldKind::Density as i32,
                components: 1,
                scalar: v1::ScalarType::F32 as i32,
                data: (0..bytes)
                    .map(|i| if i % 4 == 3 { 0x3f } else { 0 })
                    .collect(),
            }],
            bodies: Vec::new(),
            surface: None,
            solids: Vec::new(),
            solid_surfaces: Vec::new(),
        }
    }

    #[test]
    fn frames_decode_to_f32_fields() {
        let frame = FrameView::decode(&wire(2, 8).encode_to_vec()).expect("valid");
        assert_eq!(frame.step, 3);
        let density = frame.field(v1::FieldKind::Density).expect("density");
        assert_eq!(density.values, vec![0.5, 0.5]);
    }

    #[test]
    fn inconsistent_frames_are_refused() {
        let err = FrameView::from_proto(wire(3, 8)).expect_err("too short");
        assert!(err.to_string().contains("expected 12"), "{err}");
        let mut no_header = wire(2, 8);
        no_header.header = None;
        assert!(FrameView::from_proto(no_header).is_err());
    }

    #[test]
    fn solid_ranges_decode_and_are_checked() {
        let mut frame = wire(2, 8);
        let range = v1::SolidRange {
            system: 1,
            first: 1,
            count: 1,
        };
        frame.solids = vec![range];
        let decoded = FrameView::decode(&frame.encode_to_vec()).expect("valid");
        assert_eq!(decoded.solids, vec![range]);

        frame.solids[0].count = 2;
        let err = FrameView::from_proto(frame.clone()).expect_err("past particle 2");
        assert!(err.to_string().contains("system 1"), "{err}");
        frame.solids[0].first = u64::MAX;
        assert!(FrameView::from_proto(frame).is_err(), "overflow is refused");
    }

    fn le<T: Copy, const N: usize>(values: &[T], bytes: impl Fn(T) -> [u8; N]) -> Vec<u8> {
        values.iter().flat_map(|&v| bytes(v)).collect()
    }

    #[test]
    fn surfaces_decode_and_are_checked() {
        let mut frame = wire(2, 8);
        frame.surface = Some(v1::SurfaceMesh {
            vertices: le(
                &[0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                f32::to_le_bytes,
            ),
            triangles: le(&[0u32, 1, 2], u32::to_le_bytes),
            normals: Vec::new(),
        });
        let surface = FrameView::from_proto(frame.clone())
            .expect("valid")
            .surface
            .expect("a surface");
        assert_eq!(surface.vertices[1], [1.0, 0.0, 0.0]);
        assert_eq!(surface.triangles, vec![[0, 1, 2]]);

        let mut bad = frame.clone();
        bad.surface.as_mut().expect("surface").triangles = le(&[0u32, 1, 3], u32::to_le_bytes);
        let err = FrameView::from_proto(bad).expect_err("vertex 3 does not exist");
        assert!(err.to_string().contains("3 vertices"), "{err}");
        let mut bad = frame;
        bad.surface.as_mut().expect("surface").vertices.pop();
        assert!(FrameView::from_proto(bad).is_err());
    }

    #[test]
    fn solid_surfaces_decode_with_normals_and_are_checked() {
        let mut frame = wire(2, 8);
        let mesh = v1::SurfaceMesh {
            vertices: le(
                &[0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
                f32::to_le_bytes,
            ),
            triangles: le(&[0u32, 1, 2], u32::to_le_bytes),
            normals: le(
                &[0.0f32, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.6, 0.8],
                f32::to_le_bytes,
            ),
        };
        frame.solid_surfaces = vec![v1::SolidSurface {
            system: 1,
            mesh: Some(mesh),
        }];
        let decoded = FrameView::decode(&frame.encode_to_vec()).expect("valid");
        let [surface] = &decoded.solid_surfaces[..] else {
            panic!("one solid surface")
        };
        assert_eq!(surface.system, 1);
        assert_eq!(surface.mesh.normals[2], [0.0, 0.6, 0.8]);
        assert_eq!(surface.mesh.vertices[1], [1.0, 0.0, 0.0]);

        fn mesh_of(frame: &mut v1::Frame) -> &mut v1::SurfaceMesh {
            frame.solid_surfaces[0].mesh.as_mut().expect("mesh")
        }
        let mut bad = frame.clone();
        mesh_of(&mut bad).normals.truncate(24);
        let err = FrameView::from_proto(bad).expect_err("2 normals for 3 vertices");
        assert!(
            err.to_string().contains("2 normals for 3 vertices"),
            "{err}"
        );
        let mut bad = frame.clone();
        mesh_of(&mut bad).normals.clear();
        let err = FrameView::from_proto(bad).expect_err("a solid needs normals");
        assert!(err.to_string().contains("solid 1"), "{err}");
        let mut bad = frame.clone();
        mesh_of(&mut bad).normals.pop();
        assert!(FrameView::from_proto(bad).is_err(), "not whole normals");
        let mut bad = frame.clone();
        mesh_of(&mut bad).triangles = le(&[0u32, 1, 7], u32::to_le_bytes);
        let err = FrameView::from_proto(bad).expect_err("vertex 7 does not exist");
        assert!(err.to_string().contains("3 vertices"), "{err}");
        let mut bad = frame;
        bad.solid_surfaces[0].mesh = None;
        assert!(FrameView::from_proto(bad).is_err(), "no mesh");
    }
}
