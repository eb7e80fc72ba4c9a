//! Legacy VTK polydata (binary, big-endian as the format requires): points,
//! one vertex cell per particle so ParaView draws them, and every other
//! field as point data (the particle ids as `unsigned_int`).

use crate::frame::Frame;
use crate::scene::FieldKind;
use std::io::{self, Write};

fn write_f32s(out: &mut impl Write, values: &[f32]) -> io::Result<()> {
    for v in values {
        out.write_all(&v.to_be_bytes())?;
    }
    Ok(())
}

/// Writes `frame` as a legacy VTK file.
///
/// # Errors
/// I/O errors of `out`; `InvalidData` when the frame has no positions.
pub fn write_vtk(out: &mut impl Write, frame: &Frame) -> io::Result<()> {
    let positions = frame
        .field(FieldKind::Position)
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidData, "frame has no positions"))?;
    let n = frame.particle_count;
    writeln!(out, "# vtk DataFile Version 3.0")?;
    writeln!(
        out,
        "meshless frame step {} time {}",
        frame.step, frame.time
    )?;
    writeln!(out, "BINARY")?;
    writeln!(out, "DATASET POLYDATA")?;
    writeln!(out, "FIELD FieldData 1")?;
    writeln!(out, "TIME 1 1 double")?;
    out.write_all(&frame.time.to_be_bytes())?;
    writeln!(out)?;
    writeln!(out, "POINTS {n} float")?;
    write_f32s(out, &positions.values)?;
    writeln!(out)?;
    writeln!(out, "VERTICES {n} {}", 2 * n)?;
    for i in 0..n as u32 {
        out.write_all(&1u32.to_be_bytes())?;
        out.write_all(&i.to_be_bytes())?;
    }
    writeln!(out)?;
    let data: Vec<_> = frame
        .fields
        .iter()
        .filter(|f| f.kind != FieldKind::Position)
        .collect();
    if !data.is_empty() || frame.ids.is_some() {
        writeln!(out, "POINT_DATA {n}")?;
        if let Some(ids) = &frame.ids {
            writeln!(out, "SCALARS id unsigned_int 1")?;
            writeln!(out, "LOOKUP_TABLE default")?;
            for id in ids {
                out.write_all(&id.to_be_bytes())?;
            }
            writeln!(out)?;
        }
        for field in data {
            match field.components {
                3 => writeln!(out, "VECTORS {} float", field.kind.name())?,
                c => {
                    writeln!(out, "SCALARS {} float {c}", field.kind.name())?;
                    writeln!(out, "LOOKUP_TABLE default")?;
                }
            }
            write_f32s(out, &field.values)?;
            writeln!(out)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_frame::two_particles;

    #[test]
    fn vtk_has_points_vertices_and_point_data() {
        let mut bytes = Vec::new();
        write_vtk(&mut bytes, &two_particles()).expect("write");
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.starts_with("# vtk DataFile Version 3.0\n"));
        assert!(text.contains("POINTS 2 float\n"));
        assert!(text.contains("VERTICES 2 4\n"));
        assert!(text.contains("POINT_DATA 2\nSCALARS density float 1\nLOOKUP_TABLE default\n"));
        // The second point's y coordinate, big-endian, right after the header line.
        let marker = b"POINTS 2 float\n";
        let start = bytes
            .windows(marker.len())
            .position(|w| w == marker)
            .expect("points")
            + marker.len();
        let y1 = f32::from_be_bytes(bytes[start + 16..start + 20].try_into().expect("4 bytes"));
        assert_eq!(y1, 4.0);
    }

    #[test]
    fn vtk_writes_ids_as_unsigned_ints() {
        let mut frame = two_particles();
        frame.ids = Some(vec![4, 9]);
        let mut bytes = Vec::new();
        write_vtk(&mut bytes, &frame).expect("write");
        let marker = b"SCALARS id unsigned_int 1\nLOOKUP_TABLE default\n";
        let start = bytes
            .windows(marker.len())
            .position(|w| w == marker)
            .expect("ids")
            + marker.len();
        let id1 = u32::from_be_bytes(bytes[start + 4..start + 8].try_into().expect("4 bytes"));
        assert_eq!(id1, 9);
    }
}
