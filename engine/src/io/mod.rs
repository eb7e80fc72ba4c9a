//! Frame export in formats standard tools open: legacy VTK for ParaView
//! (a numbered series opens as one time series) and PLY point clouds for
//! Blender and MeshLab; surface meshes as OBJ or PLY.

mod mesh;
mod ply;
mod vtk;

use crate::frame::Frame;
use std::path::{Path, PathBuf};

pub use mesh::{
    MeshFormat, write_crack_surface, write_mesh_ply, write_obj, write_solid_surface, write_surface,
};
pub use ply::write_ply;
pub use vtk::write_vtk;

/// A file format for frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportFormat {
    /// Legacy VTK polydata, binary (`.vtk`).
    Vtk,
    /// Binary little-endian PLY point cloud (`.ply`).
    Ply,
}

impl ExportFormat {
    /// The file extension without the dot (`vtk`, `ply`), used to name
    /// frame files.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Vtk => "vtk",
            Self::Ply => "ply",
        }
    }
}

/// Writes a frame as `{dir}/frame_{step:06}.{ext}` and returns the path.
///
/// # Errors
/// Any I/O error, with the path in its message.
pub fn write_frame(dir: &Path, format: ExportFormat, frame: &Frame) -> std::io::Result<PathBuf> {
    let path = dir.join(format!("frame_{:06}.{}", frame.step, format.extension()));
    let file = std::fs::File::create(&path)
        .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))?;
    let mut out = std::io::BufWriter::new(file);
    match format {
        ExportFormat::Vtk => write_vtk(&mut out, frame),
        ExportFormat::Ply => write_ply(&mut out, frame),
    }
    .and_then(|()| std::io::Write::flush(&mut out))
    .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))?;
    Ok(path)
}

#[cfg(test)]
pub(crate) mod test_frame {
    use crate::frame::{FieldData, Frame};
    use crate::scene::FieldKind;

    pub fn two_particles() -> Frame {
        Frame {
            step: 7,
            time: 0.5,
            substeps: 2,
            substep_dt: 0.25,
            solver_iterations: 0,
            density_error: 0.0,
            capped: false,
            unconverged: 0,
            added: 0,
            particle_count: 2,
            fields: vec![
                FieldData {
                    kind: FieldKind::Position,
                    components: 3,
                    values: vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0],
                },
                FieldData {
                    kind: FieldKind::Density,
                    components: 1,
                    values: vec![1000.0, 1001.5],
                },
            ],
            bodies: Vec::new(),
            surface: None,
            solids: Vec::new(),
            solid_surfaces: Vec::new(),
            crack_surfaces: Vec::new(),
            ids: None,
        }
    }
}
