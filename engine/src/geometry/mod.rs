//! Geometry shared by the systems: triangle meshes (boundaries, obstacles,
//! reconstructed surfaces, embedded high-resolution surfaces) and analytic
//! solid shapes (rigid bodies).

mod mesh;
mod shape;

pub use mesh::TriMesh;
pub use shape::Shape;
