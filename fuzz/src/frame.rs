//! The frame decoder: a zenoh payload, decoded as the protocol's `Frame`
//! and converted to an engine frame ([`frame_from_proto`]), as `meshless
//! demo` does with every frame it receives before writing it out.

use crate::echo::assert_quotes_briefly;
use meshless_engine::Frame;
use meshless_proto::v1;
use meshless_wire::frame::{frame_from_proto, frame_to_proto};
use prost::Message;

/// Frame bytes through the decoder. A frame it accepts is consistent (its lengths
/// agree, as `assert_consistent` lists) and decoding is the inverse of encoding on it:
/// encoding it and decoding again gives a frame that encodes to the same
/// bytes. An error quotes briefly.
///
/// # Panics
/// When a property fails.
pub fn frame(data: &[u8]) {
    let Ok(message) = v1::Frame::decode(data) else {
        return;
    };
    let frame = match frame_from_proto(message) {
        Ok(frame) => frame,
        Err(e) => return assert_quotes_briefly(data, &e.to_string()),
    };
    assert_consistent(&frame);
    let wire = frame_to_proto("fuzz", &frame);
    let again = frame_from_proto(wire.clone())
        .unwrap_or_else(|e| panic!("an accepted frame, encoded again, is refused: {e}"));
    // Bytes rather than values: a NaN field value is carried, and is not
    // equal to itself.
    assert_eq!(
        frame_to_proto("fuzz", &again).encode_to_vec(),
        wire.encode_to_vec(),
        "decode(encode(frame)) differs from the frame"
    );
}

/// What every reader of a frame relies on: each field holds
/// `components x particle_count` values, with its kind's component count;
/// each solid's range lies within the particles; each surface's
/// triangles name existing vertices; each solid's surface has one normal
/// per vertex.
///
/// # Panics
/// When one does not hold.
fn assert_consistent(frame: &Frame) {
    let n = frame.particle_count;
    for (i, field) in frame.fields.iter().enumerate() {
        assert_eq!(
            field.components,
            field.kind.components(),
            "fields[{i}]: components of a {:?} field",
            field.kind
        );
        assert_eq!(
            Some(field.values.len()),
            field.components.checked_mul(n),
            "fields[{i}]: {} values for {n} particles x {} components",
            field.values.len(),
            field.components
        );
    }
    for (i, range) in frame.solids.iter().enumerate() {
        assert!(
            range
                .first
                .checked_add(range.count)
                .is_some_and(|end| end <= n),
            "solids[{i}] holds {}..+{} of {n} particles",
            range.first,
            range.count
        );
    }
    let meshes = frame
        .surface
        .iter()
        .chain(frame.solid_surfaces.iter().map(|s| &s.mesh));
    for mesh in meshes {
        let v = mesh.vertices.len();
        if let Some(t) = mesh
            .triangles
            .iter()
            .find(|t| t.iter().any(|&i| i as usize >= v))
        {
            panic!("triangle {t:?} of a surface with {v} vertices");
        }
    }
    for (i, solid) in frame.solid_surfaces.iter().enumerate() {
        assert_eq!(
            solid.normals.len(),
            solid.mesh.vertices.len(),
            "solid_surfaces[{i}]: normals per vertex"
        );
    }
}
