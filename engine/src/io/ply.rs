//! Binary little-endian PLY point clouds: one vertex element with x, y, z,
//! the particle id (`uint`) when the frame has ids, and one property per
//! scalar component of the other fields.

use crate::frame::Frame;
use crate::scene::FieldKind;
use std::io::{self, Write};

/// Writes `frame` as a PLY point cloud.
///
/// # Errors
/// I/O errors of `out`; `InvalidData` when the frame has no positions.
pub fn write_ply(out: &mut impl Write, frame: &Frame) -> io::Result<()> {
    if frame.field(FieldKind::Position).is_none() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            "frame has no positions",
        ));
    }
    writeln!(out, "ply")?;
    writeln!(out, "format binary_little_endian 1.0")?;
    writeln!(
        out,
        "comment meshless frame step {} time {}",
        frame.step, frame.time
    )?;
    writeln!(out, "element vertex {}", frame.particle_count)?;
    for field in &frame.fields {
        let names: &[&str] = match (field.kind, field.components) {
            (FieldKind::Position, _) => &["x", "y", "z"],
            (FieldKind::Velocity, _) => &["vx", "vy", "vz"],
            (kind, _) => &[kind.name()],
        };
        for name in names {
            writeln!(out, "property float {name}")?;
        }
        if field.kind == FieldKind::Position && frame.ids.is_some() {
            writeln!(out, "property uint id")?;
        }
    }
    writeln!(out, "end_header")?;
    for i in 0..frame.particle_count {
        for field in &frame.fields {
            let c = field.components;
            for v in &field.values[i * c..(i + 1) * c] {
                out.write_all(&v.to_le_bytes())?;
            }
            if let (FieldKind::Position, Some(ids)) = (field.kind, &frame.ids) {
                out.write_all(&ids[i].to_le_bytes())?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_frame::two_particles;

    #[test]
    fn ply_interleaves_fields_per_vertex() {
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &two_particles()).expect("write");
        let header_end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .expect("header")
            + 11;
        let header = String::from_utf8_lossy(&bytes[..header_end]);
        assert!(header.contains("element vertex 2\n"));
        assert!(header.contains("property float density\n"));
        let body: Vec<f32> = bytes[header_end..]
            .chunks(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect();
        assert_eq!(body, vec![0.0, 1.0, 2.0, 1000.0, 3.0, 4.0, 5.0, 1001.5]);
    }

    #[test]
    fn ply_puts_the_id_after_the_position() {
        let mut frame = two_particles();
        frame.ids = Some(vec![4, 9]);
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &frame).expect("write");
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("property float z\nproperty uint id\nproperty float density\n"));
        let header_end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .expect("header")
            + 11;
        let second = &bytes[header_end + 20..header_end + 40];
        assert_eq!(u32::from_le_bytes(second[12..16].try_into().expect("4")), 9);
        assert_eq!(
            f32::from_le_bytes(second[16..20].try_into().expect("4")),
            1001.5
        );
    }
}
