//! How triangles share edges: closure and orientation checks, and the
//! triangle across each edge, which the edge pseudo-normals of a signed
//! distance need.

use super::{MeshError, TriMesh};
use crate::math::Real;

/// How the undirected edges of a mesh are used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EdgeReport {
    /// Distinct undirected edges.
    pub edges: usize,
    /// Edges used by one triangle only (holes, open rims).
    pub boundary: usize,
    /// Edges used by more than two triangles.
    pub non_manifold: usize,
    /// Edges used by two triangles that run them the same way, i.e. whose
    /// orientations disagree.
    pub misoriented: usize,
}

impl EdgeReport {
    /// Every edge is shared by exactly two triangles running it in
    /// opposite directions.
    pub fn is_closed(&self) -> bool {
        self.boundary == 0 && self.non_manifold == 0 && self.misoriented == 0
    }
}

/// One directed edge `a -> b` of triangle `triangle` (its local edge
/// `corner`, from corner `corner` to the next), keyed by the undirected edge.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HalfEdge {
    pub(crate) key: (u32, u32),
    forward: bool,
    pub(crate) triangle: u32,
    pub(crate) corner: u8,
}

/// All half-edges, sorted so the uses of one undirected edge are adjacent.
pub(crate) fn sorted_half_edges(mesh: &TriMesh) -> Vec<HalfEdge> {
    let mut half_edges: Vec<HalfEdge> = mesh
        .triangles
        .iter()
        .enumerate()
        .flat_map(|(t, tri)| {
            (0..3).map(move |k| {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                HalfEdge {
                    key: (a.min(b), a.max(b)),
                    forward: a < b,
                    triangle: t as u32,
                    corner: k as u8,
                }
            })
        })
        .collect();
    half_edges.sort_unstable_by_key(|h| h.key);
    half_edges
}

impl TriMesh {
    /// Counts boundary, non-manifold and misoriented edges.
    pub fn edge_report(&self) -> EdgeReport {
        let mut report = EdgeReport::default();
        for group in sorted_half_edges(self).chunk_by(|a, b| a.key == b.key) {
            report.edges += 1;
            match group {
                [_] => report.boundary += 1,
                [a, b] if a.forward == b.forward => report.misoriented += 1,
                [_, _] => {}
                _ => report.non_manifold += 1,
            }
        }
        report
    }

    /// Every edge is shared by exactly two triangles with opposite
    /// orientation: the mesh bounds a volume (if it does not intersect
    /// itself, which this does not check).
    pub fn is_closed(&self) -> bool {
        self.edge_report().is_closed()
    }

    /// [`Self::is_closed`] as a `Result`, for callers that need a closed mesh.
    ///
    /// # Errors
    /// [`MeshError::NotClosed`] with the counts of offending edges.
    pub fn check_closed(&self) -> Result<(), MeshError> {
        let report = self.edge_report();
        if report.is_closed() {
            Ok(())
        } else {
            Err(MeshError::NotClosed {
                boundary: report.boundary,
                non_manifold: report.non_manifold,
                misoriented: report.misoriented,
            })
        }
    }

    /// Checks what a mesh built in code could get wrong: every index names
    /// a vertex and every coordinate is finite (the file readers check
    /// both with file and line).
    ///
    /// # Errors
    /// [`MeshError::BadTriangle`] or [`MeshError::NonFiniteVertex`].
    pub fn validate(&self) -> Result<(), MeshError> {
        if let Some(vertex) = self
            .vertices
            .iter()
            .position(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(MeshError::NonFiniteVertex { vertex });
        }
        for (triangle, tri) in self.triangles.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= self.vertices.len()) {
                return Err(MeshError::BadTriangle {
                    triangle,
                    index,
                    vertex_count: self.vertices.len(),
                });
            }
        }
        Ok(())
    }
}

/// For a closed mesh, the triangle across each local edge `k` (corner `k`
/// to corner `k + 1`) of each triangle.
///
/// # Errors
/// [`MeshError::NotClosed`] when some edge is not shared by exactly two
/// oppositely oriented triangles.
pub(crate) fn neighbours(mesh: &TriMesh) -> Result<Vec<[u32; 3]>, MeshError> {
    mesh.check_closed()?;
    let mut across = vec![[0; 3]; mesh.triangles.len()];
    for pair in sorted_half_edges(mesh).chunks_exact(2) {
        let (a, b) = (pair[0], pair[1]);
        across[a.triangle as usize][a.corner as usize] = b.triangle;
        across[b.triangle as usize][b.corner as usize] = a.triangle;
    }
    Ok(across)
}

/// Edges that mark a sharp feature of the surface: boundary and
/// non-manifold edges, and edges whose two faces' normals differ by more
/// than the angle whose cosine is `cos_angle`. Each as `(a, b)`, `a < b`.
pub(crate) fn feature_edges(mesh: &TriMesh, cos_angle: Real) -> Vec<(u32, u32)> {
    let normal = |t: u32| {
        let [a, b, c] = mesh.corners(t as usize);
        (b - a).cross(&(c - a)).try_normalize(0.0)
    };
    sorted_half_edges(mesh)
        .chunk_by(|a, b| a.key == b.key)
        .filter(|group| match group {
            [a, b] => match (normal(a.triangle), normal(b.triangle)) {
                (Some(n), Some(m)) => n.dot(&m) < cos_angle,
                _ => false,
            },
            _ => true,
        })
        .map(|group| group[0].key)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vector;

    fn tetrahedron() -> TriMesh {
        TriMesh {
            vertices: vec![Vector::zeros(), Vector::x(), Vector::y(), Vector::z()],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn a_tetrahedron_is_closed_and_each_face_has_three_neighbours() {
        let mesh = tetrahedron();
        assert_eq!(
            mesh.edge_report(),
            EdgeReport {
                edges: 6,
                ..Default::default()
            }
        );
        let across = neighbours(&mesh).expect("closed");
        // Face 0 = (0, 2, 1): edge 0-2 is shared with face 2 (0, 3, 2),
        // edge 2-1 with face 3, edge 1-0 with face 1.
        assert_eq!(across[0], [2, 3, 1]);
    }

    #[test]
    fn holes_flips_and_fins_are_counted() {
        let mut open = tetrahedron();
        open.triangles.pop();
        let err = open.check_closed().expect_err("a face is missing");
        assert_eq!(
            err,
            MeshError::NotClosed {
                boundary: 3,
                non_manifold: 0,
                misoriented: 0
            }
        );
        assert!(err.to_string().contains("3 boundary edges"), "{err}");

        let mut flipped = tetrahedron();
        flipped.triangles[3] = [1, 3, 2];
        assert_eq!(flipped.edge_report().misoriented, 3);
        assert!(!flipped.is_closed());

        let mut fin = tetrahedron();
        fin.vertices.push(Vector::new(1.0, 1.0, 1.0));
        fin.triangles.push([0, 1, 4]);
        let report = fin.edge_report();
        assert_eq!((report.non_manifold, report.boundary), (1, 2));
    }

    #[test]
    fn validate_names_bad_indices_and_non_finite_vertices() {
        let mut mesh = tetrahedron();
        mesh.triangles[2] = [0, 7, 2];
        assert_eq!(
            mesh.validate(),
            Err(MeshError::BadTriangle {
                triangle: 2,
                index: 7,
                vertex_count: 4
            })
        );
        let mut mesh = tetrahedron();
        mesh.vertices[3].y = f64::NAN;
        assert_eq!(
            mesh.validate(),
            Err(MeshError::NonFiniteVertex { vertex: 3 })
        );
    }
}
