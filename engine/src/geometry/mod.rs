//! Geometry shared by the systems: triangle meshes (boundaries, obstacles,
//! reconstructed surfaces, embedded high-resolution surfaces), read from
//! OBJ and PLY files, checked for closure, measured by signed distance and
//! sampled with particles; and the analytic solid shapes of rigid bodies.

mod bvh;
mod closest;
mod error;
mod mesh;
mod mesh_shapes;
mod mesh_solid;
pub mod read;
mod sampling;
mod sdf;
mod shape;
mod topology;

pub use error::MeshError;
pub use mesh::TriMesh;
pub use mesh_solid::MeshSolid;
pub use read::LoadedMesh;
pub use sampling::{MAX_SAMPLES, sample_surface, sample_volume, surface_candidates};
pub use sdf::{Closest, MeshSdf};
pub use shape::Shape;
pub use topology::EdgeReport;
