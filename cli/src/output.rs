//! Frame files written on a thread of their own, so neither stepping nor
//! receiving waits on the disk.

use anyhow::{Context, Result};
use meshless_engine::Frame;
use meshless_engine::io::{
    ExportFormat, MeshFormat, write_crack_surface, write_frame, write_solid_surface, write_surface,
};
use std::path::Path;
use std::sync::mpsc;
use std::thread::JoinHandle;

/// The `--format` flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Legacy VTK, for ParaView (opens the numbered files as a series).
    Vtk,
    /// PLY point clouds, for Blender and MeshLab.
    Ply,
}

impl From<Format> for ExportFormat {
    fn from(format: Format) -> Self {
        match format {
            Format::Vtk => ExportFormat::Vtk,
            Format::Ply => ExportFormat::Ply,
        }
    }
}

/// The `--surface-format` flag: how surface meshes are written, when the
/// scene's frames carry them (`[output] surface`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SurfaceFormat {
    /// Wavefront OBJ text, opened by nearly every 3D tool.
    Obj,
    /// Binary PLY with faces, smaller; Blender, MeshLab and ParaView.
    Ply,
}

impl From<SurfaceFormat> for MeshFormat {
    fn from(format: SurfaceFormat) -> Self {
        match format {
            SurfaceFormat::Obj => MeshFormat::Obj,
            SurfaceFormat::Ply => MeshFormat::Ply,
        }
    }
}

/// Files a writer produced, and where.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Written {
    pub frames: usize,
    pub surfaces: usize,
    pub solid_surfaces: usize,
    pub crack_surfaces: usize,
    /// `dir/frame_*.ext`, `dir/surface_*.ext`, `dir/solid*_*.ext` and
    /// `dir/cracks*_*.ext`.
    patterns: [String; 4],
}

impl Written {
    /// The summary lines naming the files, for `run` and `demo`.
    ///
    /// # Errors
    /// Standard output closed (see `outln!`).
    pub fn print(&self) -> std::io::Result<()> {
        let [frames, surfaces, solids, cracks] = &self.patterns;
        outln!(
            "  output            {frames}  ({} files; ParaView opens them as a series)",
            self.frames
        )?;
        if self.surfaces > 0 {
            outln!("  surfaces          {surfaces}  ({} files)", self.surfaces)?;
        }
        if self.solid_surfaces > 0 {
            outln!(
                "  solid surfaces    {solids}  ({} files, solidSYSTEM_STEP, with normals)",
                self.solid_surfaces
            )?;
        }
        if self.crack_surfaces > 0 {
            outln!(
                "  crack faces       {cracks}  ({} files, cracksSYSTEM_STEP, with normals)",
                self.crack_surfaces
            )?;
        }
        Ok(())
    }
}

/// A background writer of frame files, and of surface files for frames
/// that carry a surface (the fluid's, or solids' embedded ones).
#[derive(Debug)]
pub struct FrameFiles {
    frames: mpsc::Sender<Frame>,
    thread: JoinHandle<Result<(usize, usize, usize, usize)>>,
    patterns: [String; 4],
}

/// Whether `name` is a file a writer of this kind made: frames, the
/// fluid's surfaces, a solid's (`solid{system}_{step}`) or its cracks'
/// (`cracks{system}_{step}`).
fn written_earlier(name: &str) -> bool {
    let ext = |list: &[&str]| list.iter().any(|e| name.ends_with(e));
    let numbered = |prefix: &str| {
        name.strip_prefix(prefix).is_some_and(|rest| {
            let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
            digits > 0 && rest[digits..].starts_with('_')
        })
    };
    let solid = numbered("solid") || numbered("cracks");
    (name.starts_with("frame_") && ext(&[".vtk", ".ply"]))
        || ((name.starts_with("surface_") || solid) && ext(&[".obj", ".ply"]))
}

impl FrameFiles {
    /// Creates `dir` and removes frame and surface files an earlier run
    /// left there, so the folder holds one series.
    ///
    /// # Errors
    /// When the folder cannot be created or cleaned.
    pub fn start(dir: &Path, format: Format, surface_format: SurfaceFormat) -> Result<Self> {
        let format = ExportFormat::from(format);
        let surface_format = MeshFormat::from(surface_format);
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for entry in std::fs::read_dir(dir)? {
            let path = entry?.path();
            let name = path
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or_default();
            if written_earlier(name) {
                std::fs::remove_file(&path)
                    .with_context(|| format!("cannot remove {}", path.display()))?;
            }
        }
        let (frames, received) = mpsc::channel::<Frame>();
        let out = dir.to_path_buf();
        let thread = std::thread::spawn(move || {
            let (mut written, mut surfaces, mut solid_surfaces, mut crack_surfaces) = (0, 0, 0, 0);
            for frame in received {
                write_frame(&out, format, &frame)?;
                written += 1;
                if let Some(mesh) = &frame.surface {
                    write_surface(&out, surface_format, frame.step, mesh)?;
                    surfaces += 1;
                }
                for surface in &frame.solid_surfaces {
                    write_solid_surface(&out, surface_format, frame.step, surface)?;
                    solid_surfaces += 1;
                }
                for surface in &frame.crack_surfaces {
                    write_crack_surface(&out, surface_format, frame.step, surface)?;
                    crack_surfaces += 1;
                }
            }
            Ok((written, surfaces, solid_surfaces, crack_surfaces))
        });
        let (dir, mesh) = (dir.display(), surface_format.extension());
        Ok(Self {
            frames,
            thread,
            patterns: [
                format!("{dir}/frame_*.{}", format.extension()),
                format!("{dir}/surface_*.{mesh}"),
                format!("{dir}/solid*_*.{mesh}"),
                format!("{dir}/cracks*_*.{mesh}"),
            ],
        })
    }

    /// Queues a frame for writing.
    pub fn write(&self, frame: Frame) {
        // A send fails only if the writer stopped on an error, which
        // `finish` reports.
        let _ = self.frames.send(frame);
    }

    /// Waits for every queued frame and returns how many files were
    /// written.
    ///
    /// # Errors
    /// The first write error.
    pub fn finish(self) -> Result<Written> {
        drop(self.frames);
        let (frames, surfaces, solid_surfaces, crack_surfaces) = self
            .thread
            .join()
            .map_err(|_| anyhow::anyhow!("the frame writer panicked"))??;
        Ok(Written {
            frames,
            surfaces,
            solid_surfaces,
            crack_surfaces,
            patterns: self.patterns,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::written_earlier;

    /// A new run clears the files of an earlier one, solid surfaces
    /// included, and nothing else.
    #[test]
    fn earlier_series_files_are_recognised() {
        for name in [
            "frame_000001.vtk",
            "surface_000001.ply",
            "solid0_000001.obj",
            "solid12_000003.ply",
        ] {
            assert!(written_earlier(name), "{name}");
        }
        for name in [
            "notes.obj",
            "solid_000001.obj",
            "solidx_1.obj",
            "solid0_1.vtk",
        ] {
            assert!(!written_earlier(name), "{name}");
        }
    }
}
