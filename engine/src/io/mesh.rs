//! Triangle meshes as files: Wavefront OBJ (text, opens everywhere) and
//! binary little-endian PLY with a face list (compact; Blender, MeshLab and
//! ParaView read it). Coordinates are written as f32, like frames.

use crate::frame::SolidSurface;
use crate::geometry::TriMesh;
use crate::math::Vector;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// A file format for meshes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ text (`.obj`).
    Obj,
    /// Binary little-endian PLY with vertices and faces (`.ply`).
    Ply,
}

impl MeshFormat {
    /// The file extension without the dot (`obj`, `ply`), used to name
    /// written files.
    pub fn extension(self) -> &'static str {
        match self {
            Self::Obj => "obj",
            Self::Ply => "ply",
        }
    }
}

/// `normals` when it has one per vertex of `mesh`; an `InvalidInput`
/// error otherwise, so a file never pairs a vertex with another's normal.
fn per_vertex<'a>(
    mesh: &TriMesh,
    normals: Option<&'a [Vector]>,
) -> io::Result<Option<&'a [Vector]>> {
    match normals {
        Some(n) if n.len() != mesh.vertices.len() => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{} normals for {} vertices; a mesh needs one per vertex",
                n.len(),
                mesh.vertices.len()
            ),
        )),
        _ => Ok(normals),
    }
}

/// Writes `mesh` as OBJ: `v x y z` lines, then `f a b c` lines with
/// 1-based indices, counter-clockwise as in the mesh. With `normals` (one
/// per vertex), `vn x y z` lines follow the vertices and each face names
/// vertex `a`'s normal as `a//a`. `comment` goes on a `#` line at the top.
///
/// # Errors
/// I/O errors of `out`; `InvalidInput` when `normals` has not one entry
/// per vertex.
pub fn write_obj(
    out: &mut impl Write,
    mesh: &TriMesh,
    normals: Option<&[Vector]>,
    comment: &str,
) -> io::Result<()> {
    let normals = per_vertex(mesh, normals)?;
    writeln!(out, "# {comment}")?;
    writeln!(
        out,
        "# {} vertices, {} triangles",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    for v in &mesh.vertices {
        writeln!(out, "v {} {} {}", v.x as f32, v.y as f32, v.z as f32)?;
    }
    if let Some(normals) = normals {
        for n in normals {
            writeln!(out, "vn {} {} {}", n.x as f32, n.y as f32, n.z as f32)?;
        }
        for [a, b, c] in &mesh.triangles {
            let [a, b, c] = [a + 1, b + 1, c + 1];
            writeln!(out, "f {a}//{a} {b}//{b} {c}//{c}")?;
        }
    } else {
        for [a, b, c] in &mesh.triangles {
            writeln!(out, "f {} {} {}", a + 1, b + 1, c + 1)?;
        }
    }
    Ok(())
}

/// Writes `mesh` as binary little-endian PLY: a vertex element of float
/// x, y, z (and nx, ny, nz with `normals`, one per vertex) and a face
/// element whose `vertex_indices` are a uchar count (3) and uint indices.
/// `comment` goes on a header comment line.
///
/// # Errors
/// I/O errors of `out`; `InvalidInput` when `normals` has not one entry
/// per vertex.
pub fn write_mesh_ply(
    out: &mut impl Write,
    mesh: &TriMesh,
    normals: Option<&[Vector]>,
    comment: &str,
) -> io::Result<()> {
    let normals = per_vertex(mesh, normals)?;
    writeln!(out, "ply")?;
    writeln!(out, "format binary_little_endian 1.0")?;
    writeln!(out, "comment {comment}")?;
    writeln!(out, "element vertex {}", mesh.vertices.len())?;
    let axes: &[&str] = if normals.is_some() {
        &["x", "y", "z", "nx", "ny", "nz"]
    } else {
        &["x", "y", "z"]
    };
    for axis in axes {
        writeln!(out, "property float {axis}")?;
    }
    writeln!(out, "element face {}", mesh.triangles.len())?;
    writeln!(out, "property list uchar uint vertex_indices")?;
    writeln!(out, "end_header")?;
    for (k, v) in mesh.vertices.iter().enumerate() {
        let normal = normals.map(|n| &n[k]);
        for c in v.iter().chain(normal.into_iter().flat_map(|n| n.iter())) {
            out.write_all(&(*c as f32).to_le_bytes())?;
        }
    }
    for triangle in &mesh.triangles {
        out.write_all(&[3])?;
        for i in triangle {
            out.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}

/// Writes a mesh file at `path` in `format`.
fn write_mesh_file(
    path: PathBuf,
    format: MeshFormat,
    mesh: &TriMesh,
    normals: Option<&[Vector]>,
    comment: &str,
) -> io::Result<PathBuf> {
    let with_path = |e: io::Error| io::Error::new(e.kind(), format!("{}: {e}", path.display()));
    let file = std::fs::File::create(&path).map_err(with_path)?;
    let mut out = io::BufWriter::new(file);
    match format {
        MeshFormat::Obj => write_obj(&mut out, mesh, normals, comment),
        MeshFormat::Ply => write_mesh_ply(&mut out, mesh, normals, comment),
    }
    .and_then(|()| out.flush())
    .map_err(with_path)?;
    Ok(path)
}

/// Writes the surface of frame `step` as `{dir}/surface_{step:06}.{ext}`
/// and returns the path.
///
/// # Errors
/// Any I/O error, with the path in its message.
pub fn write_surface(
    dir: &Path,
    format: MeshFormat,
    step: u64,
    mesh: &TriMesh,
) -> io::Result<PathBuf> {
    let path = dir.join(format!("surface_{step:06}.{}", format.extension()));
    let comment = format!("meshless fluid surface, step {step}");
    write_mesh_file(path, format, mesh, None, &comment)
}

/// Writes a solid's embedded surface of frame `step`, with its normals, as
/// `{dir}/solid{system}_{step:06}.{ext}` and returns the path.
///
/// # Errors
/// Any I/O error, with the path in its message.
pub fn write_solid_surface(
    dir: &Path,
    format: MeshFormat,
    step: u64,
    surface: &SolidSurface,
) -> io::Result<PathBuf> {
    write_solid_mesh(dir, format, step, surface, "solid", "surface")
}

/// Writes a fracturing solid's crack faces of frame `step`, with their
/// normals, as `{dir}/cracks{system}_{step:06}.{ext}` and returns the path.
///
/// # Errors
/// Any I/O error, with the path in its message.
pub fn write_crack_surface(
    dir: &Path,
    format: MeshFormat,
    step: u64,
    surface: &SolidSurface,
) -> io::Result<PathBuf> {
    write_solid_mesh(dir, format, step, surface, "cracks", "crack faces")
}

/// A solid's mesh with its normals as `{dir}/{prefix}{system}_{step:06}.{ext}`.
fn write_solid_mesh(
    dir: &Path,
    format: MeshFormat,
    step: u64,
    surface: &SolidSurface,
    prefix: &str,
    what: &str,
) -> io::Result<PathBuf> {
    let SolidSurface {
        system,
        mesh,
        normals,
    } = surface;
    let path = dir.join(format!("{prefix}{system}_{step:06}.{}", format.extension()));
    let comment = format!("meshless solid {system} {what}, step {step}");
    write_mesh_file(path, format, mesh, Some(normals), &comment)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tetrahedron with coordinates that f32 holds exactly.
    fn tetrahedron() -> TriMesh {
        TriMesh {
            vertices: vec![
                Vector::new(0.0, 0.0, 0.0),
                Vector::new(1.5, 0.0, 0.0),
                Vector::new(0.0, 0.25, 0.0),
                Vector::new(0.0, 0.0, 2.0),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    /// A minimal OBJ reader: `v` and `f` lines, 1-based indices.
    fn read_obj(text: &str) -> TriMesh {
        let mut mesh = TriMesh::default();
        for line in text.lines() {
            let mut words = line.split_whitespace();
            match words.next() {
                Some("v") => {
                    let c: Vec<f64> = words.map(|w| w.parse().expect("a number")).collect();
                    mesh.vertices.push(Vector::new(c[0], c[1], c[2]));
                }
                Some("f") => {
                    let i: Vec<u32> = words.map(|w| w.parse().expect("an index")).collect();
                    mesh.triangles.push([i[0] - 1, i[1] - 1, i[2] - 1]);
                }
                _ => {}
            }
        }
        mesh
    }

    /// A minimal reader of the PLY layout above, following its header's
    /// counts.
    fn read_ply(bytes: &[u8]) -> TriMesh {
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .expect("a header")
            + 11;
        let header = std::str::from_utf8(&bytes[..end]).expect("ascii header");
        let count = |element: &str| -> usize {
            header
                .lines()
                .find_map(|l| l.strip_prefix(&format!("element {element} ")))
                .expect("element line")
                .parse()
                .expect("a count")
        };
        assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
        assert!(header.contains("property list uchar uint vertex_indices\n"));
        let (nv, nf) = (count("vertex"), count("face"));
        let body = &bytes[end..];
        assert_eq!(body.len(), 12 * nv + 13 * nf, "body size from the header");
        let f32_at = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().expect("4 bytes"));
        let u32_at = |o: usize| u32::from_le_bytes(body[o..o + 4].try_into().expect("4 bytes"));
        let vertices = (0..nv)
            .map(|v| Vector::from([0, 1, 2].map(|c| f64::from(f32_at(12 * v + 4 * c)))))
            .collect();
        let triangles = (0..nf)
            .map(|f| {
                let o = 12 * nv + 13 * f;
                assert_eq!(body[o], 3, "face {f} is a triangle");
                [0, 1, 2].map(|c| u32_at(o + 1 + 4 * c))
            })
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    #[test]
    fn obj_round_trips() {
        let mut bytes = Vec::new();
        write_obj(&mut bytes, &tetrahedron(), None, "test").expect("write");
        let text = String::from_utf8(bytes).expect("text");
        assert!(text.starts_with("# test\n# 4 vertices, 4 triangles\n"));
        assert_eq!(read_obj(&text), tetrahedron());
    }

    #[test]
    fn ply_round_trips() {
        let mut bytes = Vec::new();
        write_mesh_ply(&mut bytes, &tetrahedron(), None, "test").expect("write");
        let back = read_ply(&bytes);
        assert_eq!(back, tetrahedron());
        assert!((back.signed_volume() - 0.125).abs() < 1e-12);
    }

    #[test]
    fn surfaces_are_named_by_step() {
        let dir = std::env::temp_dir().join(format!("meshless-surface-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = write_surface(&dir, MeshFormat::Ply, 42, &tetrahedron()).expect("write");
        assert_eq!(path, dir.join("surface_000042.ply"));
        assert_eq!(
            read_ply(&std::fs::read(&path).expect("read")),
            tetrahedron()
        );
        let path = write_surface(&dir, MeshFormat::Obj, 7, &TriMesh::default()).expect("write");
        let text = std::fs::read_to_string(&path).expect("read");
        assert_eq!(read_obj(&text), TriMesh::default());
        std::fs::remove_dir_all(&dir).expect("clean up");
    }

    /// A normal per vertex of the tetrahedron, each distinct.
    fn normals() -> Vec<Vector> {
        (0..4)
            .map(|k| Vector::new(0.5 * k as f64, -1.0, 0.25))
            .collect()
    }

    /// OBJ: a `vn` line per vertex, in order, and faces that pair each
    /// vertex with its own normal.
    #[test]
    fn obj_carries_normals_per_vertex() {
        let mut bytes = Vec::new();
        write_obj(&mut bytes, &tetrahedron(), Some(&normals()), "test").expect("write");
        let text = String::from_utf8(bytes).expect("text");
        let vn: Vec<Vector> = text
            .lines()
            .filter_map(|l| l.strip_prefix("vn "))
            .map(|l| {
                let c: Vec<f64> = l.split(' ').map(|w| w.parse().expect("number")).collect();
                Vector::new(c[0], c[1], c[2])
            })
            .collect();
        assert_eq!(vn, normals());
        let faces: Vec<&str> = text.lines().filter(|l| l.starts_with("f ")).collect();
        assert_eq!(faces.len(), 4);
        assert_eq!(faces[1], "f 1//1 2//2 4//4");
        let plain = text.replace("//1", "").replace("//2", "");
        let plain = plain.replace("//3", "").replace("//4", "");
        assert_eq!(read_obj(&plain), tetrahedron(), "same vertices and faces");
    }

    /// PLY: nx, ny, nz follow x, y, z in each vertex record.
    #[test]
    fn ply_carries_normals_per_vertex() {
        let mut bytes = Vec::new();
        write_mesh_ply(&mut bytes, &tetrahedron(), Some(&normals()), "test").expect("write");
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .expect("a header")
            + 11;
        let header = std::str::from_utf8(&bytes[..end]).expect("ascii header");
        assert!(header.contains(
            "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
        ));
        let body = &bytes[end..];
        assert_eq!(body.len(), 24 * 4 + 13 * 4);
        let f32_at = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().expect("4 bytes"));
        for (k, (v, n)) in tetrahedron().vertices.iter().zip(normals()).enumerate() {
            let record = [0, 1, 2, 3, 4, 5].map(|c| f64::from(f32_at(24 * k + 4 * c)));
            assert_eq!(record, [v.x, v.y, v.z, n.x, n.y, n.z], "vertex {k}");
        }
    }

    #[test]
    fn normals_must_match_the_vertices() {
        let short = &normals()[..3];
        let err = write_obj(&mut Vec::new(), &tetrahedron(), Some(short), "t").expect_err("3 of 4");
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        assert!(
            err.to_string().contains("3 normals for 4 vertices"),
            "{err}"
        );
        assert!(write_mesh_ply(&mut Vec::new(), &tetrahedron(), Some(short), "t").is_err());
    }

    #[test]
    fn solid_surfaces_are_named_by_system_and_step() {
        let dir = std::env::temp_dir().join(format!("meshless-solid-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let surface = SolidSurface {
            system: 2,
            mesh: tetrahedron(),
            normals: normals(),
        };
        let path = write_solid_surface(&dir, MeshFormat::Obj, 9, &surface).expect("write");
        assert_eq!(path, dir.join("solid2_000009.obj"));
        let text = std::fs::read_to_string(&path).expect("read");
        assert_eq!(text.lines().filter(|l| l.starts_with("vn ")).count(), 4);
        std::fs::remove_dir_all(&dir).expect("clean up");
    }
}
