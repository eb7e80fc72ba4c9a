//! Geometry shared by the systems: triangle meshes (boundaries, obstacles,
//! reconstructed surfaces, embedded high-resolution surfaces), read from
//! OBJ and PLY files, checked for closure, measured by signed distance and
//! sampled with particles; and the analytic solid shapes of rigid bodies.

pub mod atlas;
mod bvh;
mod closest;
pub(crate) use closest::closest_point_on_triangle;
pub(crate) use topology::sorted_half_edges;
pub mod conformal;
mod error;
mod implicit;
mod mesh;
mod mesh_shapes;
mod mesh_solid;
pub mod octree;
mod points_implicit;
mod projection;
pub mod quadtree;
pub mod read;
mod sampling;
mod sdf;
mod shape;
mod topology;

pub use error::MeshError;
pub use implicit::{Ball, ImplicitSurface};
pub use mesh::{TriMesh, VertexRings, vertex_normals};
pub use mesh_solid::MeshSolid;
pub use octree::{Octree, OctreeError, OctreeParams};
pub use points_implicit::{
    MAX_NEIGHBOURS, MAX_POINTS, MAX_SUPPORT, MIN_POINTS, PointCloudError, PointSurface,
    PointSurfaceParams, SPACING_CLAMP,
};
pub use projection::{Projection, project};
pub use read::{LoadedMesh, OrientedPoints};
pub use sampling::{MAX_SAMPLES, sample_surface, sample_volume, surface_candidates};
pub use sdf::{Closest, MeshSdf};
pub use shape::Shape;
pub use topology::EdgeReport;
