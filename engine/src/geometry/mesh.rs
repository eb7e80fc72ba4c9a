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

/// Area-weighted unit vertex normals of `triangles` over `positions`:
/// each triangle adds its cross product (twice its area times its unit
/// normal) to its corners; zero for a vertex in no triangle of positive
/// area. Takes the positions apart from the triangles so that a deformed
/// surface needs no mesh of its own.
pub fn vertex_normals(triangles: &[[u32; 3]], positions: &[Vector]) -> Vec<Vector> {
    let mut normals = vec![Vector::zeros(); positions.len()];
    for tri in triangles {
        let [a, b, c] = tri.map(|i| positions[i as usize]);
        let n = (b - a).cross(&(c - a));
        for &i in tri {
            normals[i as usize] += n;
        }
    }
    for n in &mut normals {
        let norm_squared = n.norm_squared();
        *n = if norm_squared > 0.0 && norm_squared.is_finite() {
            *n * (1.0 / norm_squared.sqrt())
        } else {
            Vector::zeros()
        };
    }
    normals
}

impl TriMesh {
    /// Area-weighted unit vertex normals ([`vertex_normals`]).
    pub fn vertex_normals(&self) -> Vec<Vector> {
        vertex_normals(&self.triangles, &self.vertices)
    }

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
