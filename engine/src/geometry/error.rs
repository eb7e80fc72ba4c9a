//! What can go wrong reading a mesh or building geometry from it. Each
//! message names the file (or triangle) at fault and says what to change.

use crate::math::Real;
use std::path::PathBuf;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error("{}: cannot read the file: {message}", path.display())]
    Unreadable { path: PathBuf, message: String },

    #[error(
        "{}: unknown mesh extension {extension:?}: give a `.obj` or `.ply` file",
        path.display()
    )]
    UnknownExtension { path: PathBuf, extension: String },

    /// A malformed line or element; `location` is "line N" for OBJ and the
    /// element (with the PLY parser's own line or byte detail) for PLY.
    #[error("{}: {location}: {message}", path.display())]
    Parse {
        path: PathBuf,
        location: String,
        message: String,
    },

    #[error(
        "{}: {location}: vertex index {index} is out of range ({vertex_count} vertices{}); \
         fix the face or add the missing vertices",
        path.display(),
        if *.vertex_count == 0 { ", none defined yet" } else { "" }
    )]
    IndexOutOfRange {
        path: PathBuf,
        location: String,
        index: i64,
        vertex_count: usize,
    },

    #[error(
        "{}: {location}: coordinate {value} is not finite; every vertex needs finite x, y, z",
        path.display()
    )]
    NonFinite {
        path: PathBuf,
        location: String,
        value: Real,
    },

    #[error(
        "{}: no triangles ({vertex_count} vertices, {dropped} faces dropped as collapsed); \
         a mesh file needs `f` lines (OBJ) or a `face` element (PLY)",
        path.display()
    )]
    NoTriangles {
        path: PathBuf,
        vertex_count: usize,
        dropped: usize,
    },

    /// A mesh built in code (not read from a file) that refers to a vertex
    /// it does not have.
    #[error(
        "triangle {triangle} refers to vertex {index}, but the mesh has {vertex_count} vertices"
    )]
    BadTriangle {
        triangle: usize,
        index: u32,
        vertex_count: usize,
    },

    #[error("vertex {vertex} has a non-finite coordinate; every vertex needs finite x, y, z")]
    NonFiniteVertex { vertex: usize },

    #[error("mesh has no triangles; a signed distance needs a closed surface")]
    Empty,

    /// The mesh is not a closed, consistently oriented 2-manifold, which
    /// signed distances and volume filling need.
    #[error(
        "mesh is not closed: {boundary} boundary edges (used by one triangle), \
         {non_manifold} non-manifold edges (used by more than two) and {misoriented} \
         edges whose two triangles disagree in orientation; close the holes, weld \
         duplicated vertices and orient all faces outward"
    )]
    NotClosed {
        boundary: usize,
        non_manifold: usize,
        misoriented: usize,
    },

    #[error(
        "triangle {triangle} has zero area (its corners are collinear), so its normal is \
         undefined; remove zero-area faces from the mesh"
    )]
    ZeroAreaTriangle { triangle: usize },

    #[error("mesh encloses a non-positive volume {volume}: its faces point inward; flip them")]
    InsideOut { volume: Real },

    #[error("spacing must be finite and positive, got {spacing}")]
    InvalidSpacing { spacing: Real },

    #[error(
        "spacing {spacing} would make about {estimated} samples (at most {limit}); raise the spacing"
    )]
    TooManySamples {
        spacing: Real,
        estimated: Real,
        limit: usize,
    },
}
