//! Geometry shared by the systems: triangle meshes (boundaries, obstacles,
//! reconstructed surfaces, embedded high-resolution surfaces).

mod mesh;

pub use mesh::TriMesh;
