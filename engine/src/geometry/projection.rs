//! Points projected onto a triangle mesh: for each point, the nearest
//! triangle and the barycentric weights of the nearest point on it. What
//! embeds an oriented point cloud's samples in the surface reconstructed
//! from them (a shell's carried points find their place in the atlas
//! through the triangle under them).

use super::TriMesh;
use super::bvh::Bvh;
use super::closest::{Feature, closest_point_on_triangle};
use crate::math::{Real, Vector};
use rayon::prelude::*;

/// Where a point lands on a mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// The nearest triangle.
    pub triangle: usize,
    /// Barycentric weights of the nearest point on it (each in [0, 1],
    /// summing to 1).
    pub weights: [Real; 3],
    /// How far the point is from it.
    pub distance: Real,
}

/// Each of `points` projected onto `mesh`, in parallel; `None` for a mesh
/// without triangles or a non-finite point.
pub fn project(mesh: &TriMesh, points: &[Vector]) -> Vec<Option<Projection>> {
    if mesh.triangles.is_empty() {
        return vec![None; points.len()];
    }
    let boxes: Vec<(Vector, Vector)> = (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            (a.inf(&b).inf(&c), a.sup(&b).sup(&c))
        })
        .collect();
    let bvh = Bvh::new(&boxes);
    points
        .par_iter()
        .map(|p| {
            if !p.iter().all(|c| c.is_finite()) {
                return None;
            }
            let (triangle, d2, weights) = bvh.nearest(p, |t| {
                let corners = mesh.corners(t as usize);
                let (q, feature) = closest_point_on_triangle(p, &corners);
                ((q - p).norm_squared(), barycentric(&q, feature, &corners))
            })?;
            Some(Projection {
                triangle: triangle as usize,
                weights,
                distance: d2.sqrt(),
            })
        })
        .collect()
}

/// The barycentric weights of `q`, a point of the triangle on `feature`.
fn barycentric(q: &Vector, feature: Feature, corners: &[Vector; 3]) -> [Real; 3] {
    let mut w = [0.0; 3];
    match feature {
        Feature::Vertex(k) => w[k as usize] = 1.0,
        Feature::Edge(k) => {
            let (i, j) = (k as usize, (k as usize + 1) % 3);
            let edge = corners[j] - corners[i];
            let s = ((q - corners[i]).dot(&edge) / edge.norm_squared()).clamp(0.0, 1.0);
            w[i] = 1.0 - s;
            w[j] = s;
        }
        Feature::Face => {
            // Areas opposite each corner, over the whole (Ericson 3.4).
            let [a, b, c] = corners;
            let n = (b - a).cross(&(c - a));
            let whole = n.norm_squared();
            let wb = (q - a).cross(&(c - a)).dot(&n) / whole;
            let wc = (b - a).cross(&(q - a)).dot(&n) / whole;
            w = [1.0 - wb - wc, wb, wc];
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point above a face, beside an edge and beyond a corner of a
    /// square of two triangles: the weights rebuild the nearest point.
    #[test]
    fn the_weights_rebuild_the_nearest_point() {
        let mesh = TriMesh::grid(1, 1, |i, j| Vector::new(i as Real, j as Real, 0.0));
        let cases = [
            (Vector::new(0.3, 0.6, 2.0), Vector::new(0.3, 0.6, 0.0)),
            (Vector::new(0.5, -1.0, 0.5), Vector::new(0.5, 0.0, 0.0)),
            (Vector::new(2.0, 3.0, -1.0), Vector::new(1.0, 1.0, 0.0)),
        ];
        let points: Vec<Vector> = cases.iter().map(|c| c.0).collect();
        for ((p, nearest), found) in cases.iter().zip(project(&mesh, &points)) {
            let found = found.expect("a mesh with triangles");
            let corners = mesh.corners(found.triangle);
            let rebuilt: Vector = (0..3).map(|k| corners[k] * found.weights[k]).sum();
            assert!((rebuilt - nearest).norm() < 1e-12, "{p:?}: {rebuilt:?}");
            assert!(((p - nearest).norm() - found.distance).abs() < 1e-12);
            assert!(found.weights.iter().all(|w| (0.0..=1.0).contains(w)));
        }
        assert_eq!(project(&TriMesh::default(), &points), vec![None; 3]);
        let nan = [Vector::repeat(Real::NAN)];
        assert_eq!(project(&mesh, &nan), vec![None]);
    }
}
