//! What can go wrong reading a mesh or building geometry from it. Each
//! message names the file (or triangle) at fault and says what to change.

use crate::math::Real;
use std::path::PathBuf;

/// Why a mesh file could not be read, or a mesh could not be used for
/// signed distances or sampling.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// The file could not be opened or read.
    #[error("{}: cannot read the file: {message}", path.display())]
    Unreadable {
        /// The mesh file.
        path: PathBuf,
        /// The I/O error's text.
        message: String,
    },

    /// The extension is neither `.obj` nor `.ply` (any case).
    #[error(
        "{}: unknown mesh extension {extension:?}: give a `.obj` or `.ply` file",
        path.display()
    )]
    UnknownExtension {
        /// The mesh file.
        path: PathBuf,
        /// The extension found, lower-cased; empty when there is none.
        extension: String,
    },

    /// A malformed line or element; `location` is "line N" for OBJ and the
    /// element (with the PLY parser's own line or byte detail) for PLY.
    #[error("{}: {location}: {message}", path.display())]
    Parse {
        /// The mesh file.
        path: PathBuf,
        /// Where in the file: `line N` (OBJ), `header`, `element "..."` or
        /// `face N` (PLY).
        location: String,
        /// What is wrong there.
        message: String,
    },

    /// A face names a vertex the file does not define.
    #[error(
        "{}: {location}: vertex index {index} is out of range ({vertex_count} vertices{}); \
         fix the face or add the missing vertices",
        path.display(),
        if *.vertex_count == 0 { ", none defined yet" } else { "" }
    )]
    IndexOutOfRange {
        /// The mesh file.
        path: PathBuf,
        /// The face: `line N` (OBJ) or `face N` (PLY).
        location: String,
        /// The index as written: 1-based or negative (relative) in OBJ,
        /// 0-based in PLY.
        index: i64,
        /// Vertices defined (in OBJ, for a negative index: so far).
        vertex_count: usize,
    },

    /// A vertex coordinate is NaN or infinite.
    #[error(
        "{}: {location}: coordinate {value} is not finite; every vertex needs finite x, y, z",
        path.display()
    )]
    NonFinite {
        /// The mesh file.
        path: PathBuf,
        /// The vertex: `line N` (OBJ) or `vertex N` (PLY, 0-based).
        location: String,
        /// The first non-finite coordinate of that vertex.
        value: Real,
    },

    /// The file holds no triangle once collapsed faces are dropped.
    #[error(
        "{}: no triangles ({vertex_count} vertices, {dropped} faces dropped as collapsed); \
         a mesh file needs `f` lines (OBJ) or a `face` element (PLY)",
        path.display()
    )]
    NoTriangles {
        /// The mesh file.
        path: PathBuf,
        /// Vertices the file defines.
        vertex_count: usize,
        /// Collapsed triangles (a repeated vertex index) dropped.
        dropped: usize,
    },

    /// A mesh built in code (not read from a file) that refers to a vertex
    /// it does not have.
    #[error(
        "triangle {triangle} refers to vertex {index}, but the mesh has {vertex_count} vertices"
    )]
    BadTriangle {
        /// Index of the triangle (0-based).
        triangle: usize,
        /// The vertex index it holds (0-based), at or past `vertex_count`.
        index: u32,
        /// Vertices the mesh has.
        vertex_count: usize,
    },

    /// A mesh built in code has a vertex with a NaN or infinite coordinate.
    #[error("vertex {vertex} has a non-finite coordinate; every vertex needs finite x, y, z")]
    NonFiniteVertex {
        /// Index of the first such vertex (0-based).
        vertex: usize,
    },

    /// A signed distance was asked of a mesh with no triangles.
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
        /// Edges used by one triangle only (holes, open rims).
        boundary: usize,
        /// Edges used by more than two triangles.
        non_manifold: usize,
        /// Edges whose two triangles run them the same way.
        misoriented: usize,
    },

    /// A triangle is too thin for a normal: its area is at or below a
    /// tiny fraction of its longest edge squared, as
    /// [`crate::geometry::MeshSdf::new`] tests it.
    #[error(
        "triangle {triangle} has zero area (its corners are collinear), so its normal is \
         undefined; remove zero-area faces from the mesh"
    )]
    ZeroAreaTriangle {
        /// Index of the triangle (0-based).
        triangle: usize,
    },

    /// The mesh encloses a signed volume of zero or less: its faces point
    /// inward.
    #[error("mesh encloses a non-positive volume {volume}: its faces point inward; flip them")]
    InsideOut {
        /// The signed volume by the divergence theorem (m^3), `<= 0`.
        volume: Real,
    },

    /// A mesh so large that its volume or moments of inertia overflow.
    #[error(
        "the mesh is too large to measure: its vertices reach {extent:e} m from the origin, \
         and its moments of inertia overflow; scale it down"
    )]
    Unmeasurable {
        /// The largest coordinate of a vertex, in absolute value (m).
        extent: Real,
    },

    /// A sampling spacing that is zero, negative, NaN or infinite.
    #[error("spacing must be finite and positive, got {spacing}")]
    InvalidSpacing {
        /// The spacing given (m).
        spacing: Real,
    },

    /// Sampling at this spacing would make more than
    /// [`crate::geometry::MAX_SAMPLES`] points or candidates.
    #[error(
        "spacing {spacing} would make about {estimated} samples (at most {limit}); raise the spacing"
    )]
    TooManySamples {
        /// The spacing given (m).
        spacing: Real,
        /// Estimated samples or candidates (a float, so that a huge or
        /// NaN estimate is reported rather than overflowing).
        estimated: Real,
        /// [`crate::geometry::MAX_SAMPLES`].
        limit: usize,
    },
}
