//! Closed meshes of simple solids, for scenes that want a box or a ball
//! without a file, and as references with known area and volume.

use super::TriMesh;
use crate::math::{Real, Vector};
use std::collections::HashMap;

impl TriMesh {
    /// An open sheet of `nx x ny` quads, each split in two: vertex
    /// `(i, j)` (for `i <= nx`, `j <= ny`, stored at `j (nx + 1) + i`) at
    /// `place(i, j)`, the triangles counter-clockwise in `(i, j)`. A
    /// patch's usual test and benchmark surface (a plane, a roof, a cap).
    pub fn grid(nx: usize, ny: usize, place: impl Fn(usize, usize) -> Vector) -> TriMesh {
        let vertices = (0..=ny)
            .flat_map(|j| (0..=nx).map(move |i| (i, j)))
            .map(|(i, j)| place(i, j))
            .collect();
        let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
        let mut triangles = Vec::with_capacity(2 * nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        TriMesh {
            vertices,
            triangles,
        }
    }

    /// The axis-aligned box `[min, max]`: 8 vertices, 12 outward triangles.
    pub fn cuboid(min: Vector, max: Vector) -> TriMesh {
        let vertices = (0..8)
            .map(|i| {
                Vector::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                )
            })
            .collect();
        // Each face as a counter-clockwise quad seen from outside.
        let quads = [
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
        ];
        let triangles = quads
            .iter()
            .flat_map(|[a, b, c, d]| [[*a, *b, *c], [*a, *c, *d]])
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    /// A sphere of `radius` about `center` approximated by an icosahedron
    /// whose faces are split in four `subdivisions` times, new vertices
    /// pushed out onto the sphere: `20 * 4^subdivisions` near-equilateral
    /// triangles, all vertices on the sphere, the faces inside it.
    pub fn icosphere(center: Vector, radius: Real, subdivisions: u32) -> TriMesh {
        let phi = (1.0 + 5.0_f64.sqrt()) / 2.0;
        let mut unit: Vec<Vector> = [
            [-1.0, phi, 0.0],
            [1.0, phi, 0.0],
            [-1.0, -phi, 0.0],
            [1.0, -phi, 0.0],
            [0.0, -1.0, phi],
            [0.0, 1.0, phi],
            [0.0, -1.0, -phi],
            [0.0, 1.0, -phi],
            [phi, 0.0, -1.0],
            [phi, 0.0, 1.0],
            [-phi, 0.0, -1.0],
            [-phi, 0.0, 1.0],
        ]
        .iter()
        .map(|v| Vector::from(*v).normalize())
        .collect();
        let mut triangles: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            triangles = split_faces(&mut unit, &triangles, |a, b| (a + b).normalize());
        }
        TriMesh {
            vertices: unit.iter().map(|u| center + radius * u).collect(),
            triangles,
        }
    }

    /// Every triangle split in four at its edge midpoints, `times` times:
    /// the same surface (flat faces stay flat) with `4^times` the
    /// triangles, for meshes that must be finer than their shape needs
    /// (a surface embedded in a deforming solid).
    pub fn subdivided(&self, times: u32) -> TriMesh {
        let mut vertices = self.vertices.clone();
        let mut triangles = self.triangles.clone();
        for _ in 0..times {
            triangles = split_faces(&mut vertices, &triangles, |a, b| 0.5 * (a + b));
        }
        TriMesh {
            vertices,
            triangles,
        }
    }
}

/// One midpoint subdivision: a vertex `midpoint(a, b)` per edge (shared by
/// its two triangles), four triangles per triangle, orientation kept.
fn split_faces(
    vertices: &mut Vec<Vector>,
    triangles: &[[u32; 3]],
    midpoint: impl Fn(Vector, Vector) -> Vector,
) -> Vec<[u32; 3]> {
    let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
    let mut middle = |a: u32, b: u32, vertices: &mut Vec<Vector>| {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            vertices.push(midpoint(vertices[a as usize], vertices[b as usize]));
            (vertices.len() - 1) as u32
        })
    };
    triangles
        .iter()
        .flat_map(|&[a, b, c]| {
            let ab = middle(a, b, vertices);
            let bc = middle(b, c, vertices);
            let ca = middle(c, a, vertices);
            [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn subdividing_keeps_the_surface_and_quadruples_the_triangles() {
        let cube = TriMesh::cuboid(Vector::new(-1.0, -2.0, 0.0), Vector::new(1.0, 1.0, 0.5));
        let fine = cube.subdivided(2);
        assert_eq!(fine.triangles.len(), 16 * cube.triangles.len());
        assert!((fine.area() - cube.area()).abs() < 1e-12);
        assert!((fine.signed_volume() - cube.signed_volume()).abs() < 1e-12);
        assert!(
            crate::geometry::MeshSolid::new(&fine).is_ok(),
            "still closed"
        );
    }

    #[test]
    fn cuboid_is_closed_with_the_box_area_and_volume() {
        let mesh = TriMesh::cuboid(Vector::new(-1.0, 0.0, 2.0), Vector::new(1.0, 3.0, 2.5));
        assert!(mesh.is_closed());
        assert!((mesh.area() - 2.0 * (2.0 * 3.0 + 2.0 * 0.5 + 3.0 * 0.5)).abs() < 1e-12);
        assert!((mesh.signed_volume() - 3.0).abs() < 1e-12);
    }

    /// Area and volume converge to the sphere's from below, the volume error
    /// falling towards the fourfold per level of a second-order method, and the mesh
    /// keeps Euler's V - E + F = 2.
    #[test]
    fn icosphere_is_closed_and_converges_to_the_sphere() {
        let mut last_error = Real::INFINITY;
        for level in 0..5 {
            let mesh = TriMesh::icosphere(Vector::new(0.5, 0.0, -1.0), 2.0, level);
            let report = mesh.edge_report();
            assert!(report.is_closed(), "level {level}: {report:?}");
            let (v, e, f) = (mesh.vertices.len(), report.edges, mesh.triangles.len());
            assert_eq!(v + f, e + 2, "Euler characteristic at level {level}");
            let (area, volume) = (mesh.area(), mesh.signed_volume());
            assert!(area < 16.0 * PI && volume < 32.0 / 3.0 * PI);
            let error = (32.0 / 3.0 * PI - volume) / (32.0 / 3.0 * PI);
            assert!(
                error < last_error / 3.0,
                "level {level}: volume error {error}"
            );
            last_error = error;
        }
    }
}
