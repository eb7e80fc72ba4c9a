//! Reading triangle meshes from OBJ and PLY files.
//!
//! Both readers apply the same policy, so a mesh means the same thing
//! whichever format it came in:
//!
//! - polygons are fan-triangulated from their first corner (exact for the
//!   convex polygons modelling tools write);
//! - a triangle that repeats a vertex index is *collapsed* (a fan over a
//!   polygon that lists a corner twice makes them): it has no area and no
//!   edges of its own, so it is dropped and counted in [`LoadedMesh::dropped`];
//! - a triangle with three distinct corners is kept even when its corners
//!   are collinear, because dropping it would open the mesh along its
//!   edges; [`crate::geometry::MeshSdf::new`] rejects such meshes, sampling
//!   just gives them no points;
//! - an index out of range, a non-finite coordinate, a face of fewer than
//!   three corners and a file without any triangle are errors that name
//!   the file and the line (OBJ) or element (PLY).

mod obj;
mod ply;

use super::{MeshError, TriMesh};
use crate::math::Vector;
use std::path::Path;

/// A mesh as read, with what the reader dropped.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedMesh {
    /// The triangulated mesh, coordinates as in the file.
    pub mesh: TriMesh,
    /// Collapsed triangles (a repeated vertex index) that were dropped.
    pub dropped: usize,
}

/// Reads a mesh, choosing the format by the extension (`.obj` or `.ply`,
/// any case).
///
/// # Errors
/// See [`MeshError`]: unreadable file, unknown extension, parse errors,
/// indices out of range, non-finite coordinates, no triangles.
pub fn load(path: &Path) -> Result<LoadedMesh, MeshError> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let unreadable = |e: std::io::Error| MeshError::Unreadable {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    match extension.as_str() {
        "obj" => {
            // Lossy: a stray Latin-1 byte in a comment or name is no reason
            // to refuse the geometry.
            let bytes = std::fs::read(path).map_err(unreadable)?;
            obj::parse(path, &String::from_utf8_lossy(&bytes))
        }
        "ply" => {
            let file = std::fs::File::open(path).map_err(unreadable)?;
            ply::parse(path, &mut std::io::BufReader::new(file))
        }
        _ => Err(MeshError::UnknownExtension {
            path: path.to_path_buf(),
            extension,
        }),
    }
}

impl TriMesh {
    /// Reads an OBJ or PLY mesh; see [`load`] for the policy and
    /// [`LoadedMesh::dropped`] for the count of collapsed faces dropped.
    ///
    /// # Errors
    /// As [`load`].
    pub fn from_path(path: &Path) -> Result<TriMesh, MeshError> {
        load(path).map(|loaded| loaded.mesh)
    }
}

/// Collects triangles from polygons whose indices are already checked.
#[derive(Debug, Default)]
struct Triangulator {
    triangles: Vec<[u32; 3]>,
    dropped: usize,
}

impl Triangulator {
    /// Fans `polygon` (at least three checked indices) from its first corner.
    fn add_polygon(&mut self, polygon: &[u32]) {
        for k in 1..polygon.len() - 1 {
            let t = [polygon[0], polygon[k], polygon[k + 1]];
            if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
                self.dropped += 1;
            } else {
                self.triangles.push(t);
            }
        }
    }

    fn finish(self, path: &Path, vertices: Vec<Vector>) -> Result<LoadedMesh, MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::NoTriangles {
                path: path.to_path_buf(),
                vertex_count: vertices.len(),
                dropped: self.dropped,
            });
        }
        Ok(LoadedMesh {
            mesh: TriMesh {
                vertices,
                triangles: self.triangles,
            },
            dropped: self.dropped,
        })
    }
}

/// The first non-finite coordinate of `v`, if any.
fn non_finite(v: &Vector) -> Option<crate::math::Real> {
    v.iter().copied().find(|x| !x.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_extension_and_missing_file_are_named() {
        let err = load(Path::new("shape.stl")).expect_err("stl is not read");
        assert!(
            matches!(&err, MeshError::UnknownExtension { extension, .. } if extension == "stl")
        );
        assert!(err.to_string().contains(".obj"), "{err}");
        let err = load(Path::new("/nonexistent/dir/shape.OBJ")).expect_err("missing");
        assert!(matches!(err, MeshError::Unreadable { .. }), "{err}");
        assert!(
            err.to_string().contains("/nonexistent/dir/shape.OBJ"),
            "{err}"
        );
    }

    #[test]
    fn fans_polygons_and_drops_collapsed_triangles() {
        let mut t = Triangulator::default();
        t.add_polygon(&[0, 1, 2, 3, 4]);
        assert_eq!(t.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
        t.add_polygon(&[5, 6, 6, 7]);
        assert_eq!(t.dropped, 1);
        assert_eq!(t.triangles[3], [5, 6, 7]);
    }
}
