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
/// area; a triangle naming a vertex past `positions` is left out. Takes
/// the positions apart from the triangles so that a deformed surface
/// needs no mesh of its own; a surface deformed every frame keeps its
/// [`VertexRings`] instead.
pub fn vertex_normals(triangles: &[[u32; 3]], positions: &[Vector]) -> Vec<Vector> {
    let mut normals = vec![Vector::zeros(); positions.len()];
    for tri in triangles {
        if let [Some(a), Some(b), Some(c)] = tri.map(|i| positions.get(i as usize)) {
            let n = (b - a).cross(&(c - a));
            for &i in tri {
                normals[i as usize] += n;
            }
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

/// Each vertex's incident triangles: the stencil of [`vertex_normals`]
/// for a mesh that deforms every frame. Built once, it splits the
/// normals into two parallel passes with no scattered writes: every
/// triangle's cross product, then every vertex's sum over its ring.
/// Both keep f32, what frames ship normals in
/// (`proto/meshless/v1/frame.proto`): the cross products stay in f64 (the
/// edges are differences of nearby positions), their sums and the
/// normalisation do not need it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VertexRings {
    /// The triangles whose corners are all vertices.
    triangles: Vec<[u32; 3]>,
    /// `offsets[v]..offsets[v + 1]` index `rings` for vertex `v`.
    offsets: Vec<u32>,
    /// Indices into `triangles` of the triangles around each vertex.
    rings: Vec<u32>,
}

/// Triangles or vertices per parallel task of
/// [`VertexRings::normals_into`]: tens of microseconds of work each.
const PER_TASK: usize = 4096;

impl VertexRings {
    /// The rings of `triangles` over `vertices` vertices; a triangle
    /// naming a vertex at or past `vertices` is left out.
    pub fn new(triangles: &[[u32; 3]], vertices: usize) -> Self {
        let triangles: Vec<[u32; 3]> = triangles
            .iter()
            .filter(|t| t.iter().all(|&i| (i as usize) < vertices))
            .copied()
            .collect();
        let mut offsets = vec![0u32; vertices + 1];
        for t in &triangles {
            for &v in t {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..vertices {
            offsets[v + 1] += offsets[v];
        }
        let mut next = offsets.clone();
        let mut rings = vec![0u32; offsets[vertices] as usize];
        for (t, corners) in triangles.iter().enumerate() {
            for &v in corners {
                rings[next[v as usize] as usize] = t as u32;
                next[v as usize] += 1;
            }
        }
        Self {
            triangles,
            offsets,
            rings,
        }
    }

    /// The area-weighted unit normals of [`vertex_normals`] at
    /// `positions` into `out`, to f32 precision; `faces` is scratch for
    /// the triangles' cross products.
    ///
    /// # Panics
    /// When `positions` is not one per vertex the rings were built for.
    pub fn normals_into(
        &self,
        positions: &[Vector],
        faces: &mut Vec<[f32; 3]>,
        out: &mut Vec<Vector>,
    ) {
        use rayon::prelude::*;
        assert_eq!(
            positions.len() + 1,
            self.offsets.len(),
            "one position per vertex"
        );
        faces.resize(self.triangles.len(), [0.0; 3]);
        faces
            .par_chunks_mut(PER_TASK)
            .zip(self.triangles.par_chunks(PER_TASK))
            .for_each(|(faces, triangles)| {
                for (f, &[a, b, c]) in faces.iter_mut().zip(triangles) {
                    let a = positions[a as usize];
                    let n = (positions[b as usize] - a).cross(&(positions[c as usize] - a));
                    *f = [n.x as f32, n.y as f32, n.z as f32];
                }
            });
        let faces = &*faces;
        out.resize(positions.len(), Vector::zeros());
        out.par_chunks_mut(PER_TASK)
            .enumerate()
            .for_each(|(task, out)| {
                let first = task * PER_TASK;
                for (k, n) in out.iter_mut().enumerate() {
                    let v = first + k;
                    let mut sum = [0f32; 3];
                    for &t in &self.rings[self.offsets[v] as usize..self.offsets[v + 1] as usize] {
                        let f = faces[t as usize];
                        for a in 0..3 {
                            sum[a] += f[a];
                        }
                    }
                    let [x, y, z] = sum;
                    let norm_squared = x * x + y * y + z * z;
                    let inverse = if norm_squared > 0.0 && norm_squared.is_finite() {
                        1.0 / norm_squared.sqrt()
                    } else {
                        0.0
                    };
                    *n = Vector::new(x.into(), y.into(), z.into()) * Real::from(inverse);
                }
            });
    }
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
    fn vertex_normals_weigh_each_triangle_by_its_area() {
        // Two triangles meet at vertex 0: a unit one in the xy plane and a
        // doubled one in the xz plane; vertex 4 is in no triangle.
        let positions = vec![
            Vector::zeros(),
            Vector::x(),
            Vector::y(),
            Vector::new(0.0, 0.0, 2.0),
            Vector::x(),
        ];
        let triangles = [[0, 1, 2], [0, 3, 1]];
        let normals = vertex_normals(&triangles, &positions);
        // Cross products (0, 0, 1) and (0, 2, 0): the sum (0, 2, 1).
        let expected = Vector::new(0.0, 2.0, 1.0).normalize();
        assert!((normals[0] - expected).norm() < 1e-15, "{:?}", normals[0]);
        assert!((normals[1] - expected).norm() < 1e-15, "{:?}", normals[1]);
        assert_eq!(normals[2], Vector::z());
        assert_eq!(normals[3], Vector::y());
        assert_eq!(normals[4], Vector::zeros());
        // A triangle naming a missing vertex is left out.
        let ignored = vertex_normals(&[[0, 1, 2], [0, 1, 9]], &positions);
        assert_eq!(ignored[2], Vector::z());
        assert_eq!(ignored[0], Vector::z());
    }

    #[test]
    fn the_rings_give_the_scattered_normals_to_f32() {
        let mut sphere = TriMesh::icosphere(Vector::zeros(), 1.0, 3);
        let mut seed = 3;
        for v in &mut sphere.vertices {
            *v *= 1.0 + 0.2 * crate::testing::uniform(&mut seed);
        }
        // A vertex in no triangle: zero from both.
        sphere.vertices.push(Vector::x());
        let rings = VertexRings::new(&sphere.triangles, sphere.vertices.len());
        let (mut faces, mut normals) = (Vec::new(), Vec::new());
        rings.normals_into(&sphere.vertices, &mut faces, &mut normals);
        let reference = sphere.vertex_normals();
        assert_eq!(normals.len(), reference.len());
        assert_eq!(normals.last(), Some(&Vector::zeros()));
        for (v, (n, r)) in normals.iter().zip(&reference).enumerate() {
            assert!((n - r).norm() < 1e-6, "vertex {v}: {n:?} vs {r:?}");
        }
    }

    #[test]
    fn every_vertex_of_a_sphere_points_out() {
        let sphere = TriMesh::icosphere(Vector::zeros(), 1.0, 3);
        for (v, n) in sphere.vertex_normals().iter().enumerate() {
            let radial = sphere.vertices[v].normalize();
            assert!(n.dot(&radial) > 0.99, "vertex {v}: {n:?}");
        }
    }

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
