//! An indexed triangle mesh, the one mesh type of the engine: boundaries
//! and obstacles are read into it, surfaces are reconstructed into it, and
//! every mesh file is written from it.

use crate::math::{Real, Vector};

/// Vertices and counter-clockwise triangles (outward normals by the right
/// hand rule).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions, in the length unit of the file or scene (m).
    pub vertices: Vec<Vector>,
    /// Corner indices into `vertices`, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// The three corners of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vector; 3] {
        self.triangles[t].map(|i| self.vertices[i as usize])
    }

    /// Total surface area.
    pub fn area(&self) -> Real {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    /// Enclosed volume by the divergence theorem; exact for a closed,
    /// consistently oriented mesh, positive when the normals point out.
    pub fn signed_volume(&self) -> Real {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit right tetrahedron: area 1.5 + sqrt(3)/2, volume 1/6.
    #[test]
    fn tetrahedron_area_and_volume() {
        let mesh = TriMesh {
            vertices: vec![Vector::zeros(), Vector::x(), Vector::y(), Vector::z()],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        };
        assert!((mesh.area() - (1.5 + 3.0_f64.sqrt() / 2.0)).abs() < 1e-12);
        assert!((mesh.signed_volume() - 1.0 / 6.0).abs() < 1e-12);
    }
}
