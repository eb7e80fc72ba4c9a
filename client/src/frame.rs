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
    /// Checks a surface message without unpacking it: the same checks as
    /// [`SurfaceView::from_proto`].
    ///
    /// # Errors
    /// As [`SurfaceView::from_proto`].
    pub fn check(surface: &v1::SurfaceMesh) -> Result<(), ClientError> {
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
        let vertex_count = vertices.len() / 12;
        let bad = triangles
            .chunks_exact(12)
            .map(|c| [0, 4, 8].map(|o| u32::from_le_bytes([c[o], c[o + 1], c[o + 2], c[o + 3]])))
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= vertex_count));
        if let Some((t, triangle)) = bad {
            return Err(ClientError::Decode(format!(
                "surface triangle {t} is {triangle:?}, but there are {vertex_count} vertices"
            )));
        }
        Ok(())
    }

    /// Unpacks a surface message.
    ///
    /// # Errors
    /// [`ClientError::Decode`] when a byte count is not whole vertices,
    /// normals or triangles, there are normals but not one per vertex, or
    /// a triangle names a vertex that does not exist.
    pub fn from_proto(surface: v1::SurfaceMesh) -> Result<Self, ClientError> {
        Self::check(&surface)?;
        Ok(Self::unpack(&surface))
    }

    /// The arrays of a surface [`SurfaceView::check`] passed.
    fn unpack(surface: &v1::SurfaceMesh) -> Self {
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
        Self {
            vertices: floats(&surface.vertices),
            triangles: triples(&surface.triangles)
                .into_iter()
                .map(|t| t.map(u32::from_le_bytes))
                .collect(),
            normals: floats(&surface.normals),
        }
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
    /// Checks a solid surface message without unpacking it: the same
    /// checks as [`SolidSurfaceView::from_proto`].
    ///
    /// # Errors
    /// As [`SolidSurfaceView::from_proto`].
    pub fn check(surface: &v1::SolidSurface) -> Result<(), ClientError> {
        let system = surface.system;
        let mesh = surface.mesh.as_ref().ok_or_else(|| no_mesh(system))?;
        SurfaceView::check(mesh)
            .map_err(|e| ClientError::Decode(format!("solid {system}: {e}")))?;
        if mesh.normals.len() != mesh.vertices.len() {
            return Err(ClientError::Decode(format!(
                "solid {system}'s surface has {} normals for {} vertices; it needs one per vertex",
                mesh.normals.len() / 12,
                mesh.vertices.len() / 12
            )));
        }
        Ok(())
    }

    /// Unpacks a solid surface message.
    ///
    /// # Errors
    /// [`ClientError::Decode`] when the mesh is missing or inconsistent,
    /// or lacks its normals.
    pub fn from_proto(surface: v1::SolidSurface) -> Result<Self, ClientError> {
        Self::check(&surface)?;
        let v1::SolidSurface { system, mesh } = surface;
        let mesh = SurfaceView::unpack(&mesh.ok_or_else(|| no_mesh(system))?);
        Ok(Self { system, mesh })
    }
}

fn no_mesh(system: u32) -> ClientError {
    ClientError::Decode(format!("solid {system}'s surface has no mesh"))
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
    /// Whether the scene's `time.max_substeps` capped the last step, so
    /// its sub-steps exceeded the stability limit.
    pub capped: bool,
    /// Solves of the last step that stopped at their iteration cap above
    /// their tolerance.
    pub unconverged: u32,
    /// Particles the systems gained at the start of the last step (ids
    /// after their system's last): a resampling solid's, a fluid's.
    pub added: u32,
    /// The real-valued particle fields: position first, then the scene's
    /// `output.fields`, each once.
    pub fields: Vec<FieldView>,
    /// Each particle's stable id within its system, row for row with
    /// `fields`, when the scene's `output.fields` names `id`: a particle
    /// keeps its id from frame to frame while others leave or join, so
    /// this is how a client follows one.
    pub ids: Option<Vec<u32>>,
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
    /// The crack faces of every fracturing solid that has cracks, in
    /// scene order.
    pub crack_surfaces: Vec<SolidSurfaceView>,
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

    /// Checks a frame message without unpacking it: the same checks as
    /// [`FrameView::from_proto`], for programs that keep the message
    /// (`meshless demo` hands it to `meshless-wire`).
    ///
    /// # Errors
    /// As [`FrameView::from_proto`].
    pub fn check(frame: &v1::Frame) -> Result<(), ClientError> {
        let header = frame.header.as_ref().ok_or_else(no_header)?;
        let particle_count = header_particles(header)?;
        for field in &frame.fields {
            field_kind(field, particle_count)?;
        }
        check_solids(&frame.solids, particle_count)?;
        if let Some(surface) = &frame.surface {
            SurfaceView::check(surface)?;
        }
        frame
            .solid_surfaces
            .iter()
            .chain(&frame.crack_surfaces)
            .try_for_each(SolidSurfaceView::check)
    }

    /// Checks and unpacks a frame message.
    ///
    /// # Errors
    /// [`ClientError::Decode`] for a missing header or one that names no
    /// session, an unknown field kind or scalar type, a field whose size
    /// does not match the particle count, a solid's range past the last
    /// particle, or an inconsistent surface (the fluid's or a solid's).
    pub fn from_proto(frame: v1::Frame) -> Result<Self, ClientError> {
        let v1::Frame {
            header,
            fields,
            bodies,
            surface,
            solids,
            solid_surfaces,
            crack_surfaces,
        } = frame;
        let header = header.ok_or_else(no_header)?;
        let particle_count = header_particles(&header)?;
        let v1::FrameHeader {
            session_id,
            step,
            time,
            particle_count: _,
            substeps,
            substep_dt,
            fields: _,
            solver_iterations,
            density_error,
            capped,
            unconverged,
            added,
        } = header;
        let mut real = Vec::with_capacity(fields.len());
        let mut ids = None;
        for field in fields {
            let kind = field_kind(&field, particle_count)?;
            let words = field.data.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]);
            if kind == v1::FieldKind::Id {
                if ids.is_some() {
                    return Err(ClientError::Decode("two id fields in one frame".into()));
                }
                ids = Some(words.map(u32::from_le_bytes).collect());
            } else {
                real.push(FieldView {
                    kind,
                    components: field.components as usize,
                    values: words.map(f32::from_le_bytes).collect(),
                });
            }
        }
        check_solids(&solids, particle_count)?;
        Ok(Self {
            session_id,
            step,
            time,
            particle_count,
            substeps,
            substep_dt,
            solver_iterations,
            density_error,
            capped,
            unconverged,
            added,
            fields: real,
            ids,
            bodies,
            surface: surface.map(SurfaceView::from_proto).transpose()?,
            solids,
            solid_surfaces: solid_surfaces
                .into_iter()
                .map(SolidSurfaceView::from_proto)
                .collect::<Result<_, _>>()?,
            crack_surfaces: crack_surfaces
                .into_iter()
                .map(SolidSurfaceView::from_proto)
                .collect::<Result<_, _>>()?,
        })
    }

    /// The real-valued field of a kind, if the frame carries it (ids are
    /// in [`FrameView::ids`]).
    pub fn field(&self, kind: v1::FieldKind) -> Option<&FieldView> {
        self.fields.iter().find(|f| f.kind == kind)
    }

    /// The row of the particle with `id`, if the frame carries ids and
    /// that particle: ids within a system are unique, so `system`'s rows
    /// (`None`: the fluid's, before the first solid's) narrow the search.
    pub fn row_of(&self, system: Option<u32>, id: u32) -> Option<usize> {
        let ids = self.ids.as_ref()?;
        let rows = match system {
            Some(system) => {
                let range = self.solids.iter().find(|r| r.system == system)?;
                range.first as usize..(range.first + range.count) as usize
            }
            None => 0..self.solids.first().map_or(ids.len(), |r| r.first as usize),
        };
        rows.clone().find(|&row| ids[row] == id)
    }
}

fn no_header() -> ClientError {
    ClientError::Decode("no header".into())
}

/// The particle count of a frame's header, after checking that it names
/// its session and that the count fits this machine's `usize`.
fn header_particles(header: &v1::FrameHeader) -> Result<usize, ClientError> {
    if header.session_id.is_empty() {
        return Err(ClientError::Decode("the header names no session".into()));
    }
    let count = header.particle_count;
    usize::try_from(count).map_err(|_| ClientError::Decode(format!("particle count {count}")))
}

/// A field's kind, after checking its scalar type (u32 for ids, f32 for
/// the rest) and that its bytes are exactly `particle_count` x
/// `components` 4-byte scalars (the product checked for overflow: both
/// counts come from the sender).
fn field_kind(field: &v1::FieldData, particle_count: usize) -> Result<v1::FieldKind, ClientError> {
    let v1::FieldData {
        kind,
        components,
        scalar,
        data,
    } = field;
    let kind = v1::FieldKind::try_from(*kind)
        .map_err(|_| ClientError::Decode(format!("unknown field kind {kind}")))?;
    let expected_scalar = if kind == v1::FieldKind::Id {
        v1::ScalarType::U32
    } else {
        v1::ScalarType::F32
    };
    if *scalar != expected_scalar as i32 {
        return Err(ClientError::Decode(format!(
            "field {kind:?} has scalar type {scalar}, expected {expected_scalar:?}"
        )));
    }
    let expected = (*components as usize)
        .checked_mul(particle_count)
        .and_then(|n| n.checked_mul(4));
    if expected != Some(data.len()) {
        let expected = expected.map_or_else(|| "more than memory holds".into(), |n| n.to_string());
        return Err(ClientError::Decode(format!(
            "field {kind:?} has {} bytes, expected {expected} for {particle_count} particles x {components}",
            data.len()
        )));
    }
    Ok(kind)
}

/// Checks that every solid's range lies within the frame's particles.
fn check_solids(solids: &[v1::SolidRange], particle_count: usize) -> Result<(), ClientError> {
    match solids.iter().find(|r| {
        r.first
            .checked_add(r.count)
            .is_none_or(|end| end > particle_count as u64)
    }) {
        Some(range) => Err(ClientError::Decode(format!(
            "solid of system {} holds particles {}..+{}, past the frame's {particle_count}",
            range.system, range.first, range.count
        ))),
        None => Ok(()),
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
                capped: false,
                unconverged: 0,
                added: 0,
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
            crack_surfaces: Vec::new(),
        }
    }

    #[test]
    fn frames_decode_to_f32_fields() {
        let frame = FrameView::decode(&wire(2, 8).encode_to_vec()).expect("valid");
        assert_eq!(frame.step, 3);
        let density = frame.field(v1::FieldKind::Density).expect("density");
        assert_eq!(density.values, vec![0.5, 0.5]);
    }

    /// `wire(particles, ..)` with an id field of `ids` before the density
    /// and the last `solid` particles in a solid's range.
    fn with_ids(ids: &[u32], solid: u64) -> v1::Frame {
        let n = ids.len() as u64;
        let mut frame = wire(n, 4 * ids.len());
        frame.fields.insert(
            0,
            v1::FieldData {
                kind: v1::FieldKind::Id as i32,
                components: 1,
                scalar: v1::ScalarType::U32 as i32,
                data: ids.iter().flat_map(|id| id.to_le_bytes()).collect(),
            },
        );
        frame.solids.push(v1::SolidRange {
            system: 1,
            first: n - solid,
            count: solid,
        });
        frame
    }

    #[test]
    fn ids_decode_as_integers_and_find_their_rows() {
        let frame =
            FrameView::decode(&with_ids(&[0, 2, 7, 0, 1], 2).encode_to_vec()).expect("valid");
        assert_eq!(frame.ids.as_deref(), Some(&[0, 2, 7, 0, 1][..]));
        assert_eq!(frame.fields.len(), 1, "ids are not among the real fields");
        assert_eq!(frame.row_of(None, 7), Some(2));
        assert_eq!(frame.row_of(None, 1), None, "id 1 is the solid's");
        assert_eq!(frame.row_of(Some(1), 0), Some(3));
        assert_eq!(frame.row_of(Some(1), 1), Some(4));
        assert_eq!(frame.row_of(Some(4), 0), None, "no system 4");
        let mut as_real = with_ids(&[0, 1], 1);
        as_real.fields[0].scalar = v1::ScalarType::F32 as i32;
        let err = FrameView::from_proto(as_real).expect_err("ids are u32");
        assert!(err.to_string().contains("expected U32"), "{err}");
        let mut twice = with_ids(&[0, 1], 1);
        twice.fields.push(twice.fields[0].clone());
        let err = FrameView::from_proto(twice).expect_err("ids once");
        assert!(err.to_string().contains("two id fields"), "{err}");
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
    /// Every malformed frame `check` refuses, `from_proto` refuses, and
    /// the other way round: the subscribers' `recv_message` (which checks)
    /// and `recv` (which unpacks) drop the same frames.
    #[test]
    fn check_agrees_with_from_proto() {
        let mut cases = vec![("valid", wire(2, 8)), ("short field", wire(3, 8))];
        let mut no_header = wire(2, 8);
        no_header.header = None;
        cases.push(("no header", no_header));
        let mut nameless = wire(2, 8);
        nameless.header.as_mut().expect("header").session_id.clear();
        cases.push(("no session", nameless));
        let mut kind = wire(2, 8);
        kind.fields[0].kind = 999;
        cases.push(("unknown kind", kind));
        let mut scalar = wire(2, 8);
        scalar.fields[0].scalar = 999;
        cases.push(("unknown scalar", scalar));
        let mut range = wire(2, 8);
        range.solids = vec![v1::SolidRange {
            system: 1,
            first: 2,
            count: 1,
        }];
        cases.push(("range past the end", range));
        let mut surface = wire(2, 8);
        surface.surface = Some(v1::SurfaceMesh {
            vertices: vec![0; 12],
            triangles: le(&[0u32, 0, 1], u32::to_le_bytes),
            normals: Vec::new(),
        });
        cases.push(("triangle past the vertices", surface));
        let mut solid = wire(2, 8);
        solid.solid_surfaces = vec![v1::SolidSurface {
            system: 1,
            mesh: None,
        }];
        cases.push(("solid without a mesh", solid));
        for (what, frame) in cases {
            let checked = FrameView::check(&frame).map_err(|e| e.to_string());
            let unpacked = FrameView::from_proto(frame)
                .map(drop)
                .map_err(|e| e.to_string());
            assert_eq!(checked, unpacked, "{what}");
            assert_eq!(checked.is_ok(), what == "valid", "{what}: {checked:?}");
        }
    }

    /// The particle count and components come from the sender; their
    /// product overflowing is a refused frame, never a panic or a
    /// wrapped length that happens to match the data.
    #[test]
    fn a_field_size_that_overflows_is_refused() {
        let mut frame = wire(2, 8);
        frame.header.as_mut().expect("header").particle_count = 1 << 62;
        frame.fields[0].components = 4;
        frame.fields[0].data.clear();
        let err = FrameView::check(&frame).expect_err("4 x 4 x 2^62 bytes overflow");
        assert!(err.to_string().contains("more than memory holds"), "{err}");
        assert!(FrameView::from_proto(frame).is_err());
    }
}
