//! Signed distance to a closed triangle mesh.
//!
//! The distance is that to the nearest triangle, found through a
//! [`Bvh`]. Its sign comes from the angle-weighted pseudo-normal of the
//! feature (face, edge or vertex) holding the closest point (Bærentzen &
//! Aanæs, "Signed distance computation using the angle weighted
//! pseudonormal", IEEE TVCG 11(3), 2005): for a closed, consistently
//! oriented manifold, `(p - c) . n >= 0` exactly when `p` is outside, where
//! `c` is the closest point and `n` is
//! - on a face, its normal;
//! - on an edge, the sum of the two faces' unit normals;
//! - on a vertex, the sum of the unit normals of its faces, each weighted
//!   by the face's angle at the vertex.
//!
//! Those normals are precomputed, so a query costs one tree search.

use super::bvh::Bvh;
use super::closest::{Feature, closest_point_on_triangle};
use super::topology::neighbours;
use super::{MeshError, TriMesh};
use crate::math::{Real, Vector};

/// Triangles whose area is below this fraction of their longest edge
/// squared are taken as degenerate: their normal is noise.
const DEGENERATE_AREA: Real = 1e-12;

/// A closed mesh prepared for signed-distance queries. Immutable once
/// built, so queries run from any number of threads (`Sync`).
#[derive(Debug, Clone)]
pub struct MeshSdf {
    mesh: TriMesh,
    bvh: Bvh,
    /// Unit outward normal of each triangle.
    face_normals: Vec<Vector>,
    /// Pseudo-normal of each triangle's edge k (corner k to k + 1).
    edge_normals: Vec<[Vector; 3]>,
    /// Angle-weighted pseudo-normal of each vertex.
    vertex_normals: Vec<Vector>,
    min: Vector,
    max: Vector,
}

/// The answer to a signed-distance query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Closest {
    /// The closest point on the surface.
    pub point: Vector,
    /// Signed distance to it: negative inside.
    pub distance: Real,
    /// Unit gradient of the signed distance: from the closest point towards
    /// the query point when outside, away from it when inside, and the
    /// feature's pseudo-normal on the surface (within round-off of it).
    /// Points outward.
    pub normal: Vector,
    /// The triangle holding the closest point.
    pub triangle: usize,
}

impl MeshSdf {
    /// Prepares `mesh` (copied) for queries.
    ///
    /// # Errors
    /// [`MeshError::BadTriangle`] / [`MeshError::NonFiniteVertex`] for a
    /// malformed mesh, [`MeshError::Empty`] without triangles,
    /// [`MeshError::NotClosed`] when some edge is not shared by two
    /// oppositely oriented triangles,
    /// [`MeshError::ZeroAreaTriangle`] for a degenerate triangle, and
    /// [`MeshError::InsideOut`] when the faces point inward.
    pub fn new(mesh: &TriMesh) -> Result<MeshSdf, MeshError> {
        mesh.validate()?;
        if mesh.triangles.is_empty() {
            return Err(MeshError::Empty);
        }
        let across = neighbours(mesh)?;
        let mut face_normals = Vec::with_capacity(mesh.triangles.len());
        for t in 0..mesh.triangles.len() {
            let [a, b, c] = mesh.corners(t);
            let n = (b - a).cross(&(c - a));
            let longest = (b - a)
                .norm_squared()
                .max((c - b).norm_squared())
                .max((a - c).norm_squared());
            if n.norm() <= 2.0 * DEGENERATE_AREA * longest {
                return Err(MeshError::ZeroAreaTriangle { triangle: t });
            }
            face_normals.push(n.normalize());
        }
        let volume = mesh.signed_volume();
        if volume <= 0.0 {
            return Err(MeshError::InsideOut { volume });
        }
        let edge_normals = (0..mesh.triangles.len())
            .map(|t| across[t].map(|u| face_normals[t] + face_normals[u as usize]))
            .collect();
        let mut vertex_normals = vec![Vector::zeros(); mesh.vertices.len()];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let corners = mesh.corners(t);
            for k in 0..3 {
                let e1 = corners[(k + 1) % 3] - corners[k];
                let e2 = corners[(k + 2) % 3] - corners[k];
                vertex_normals[tri[k] as usize] += e1.angle(&e2) * face_normals[t];
            }
        }
        let boxes: Vec<(Vector, Vector)> = (0..mesh.triangles.len())
            .map(|t| {
                let [a, b, c] = mesh.corners(t);
                (a.inf(&b).inf(&c), a.sup(&b).sup(&c))
            })
            .collect();
        let (min, max) = boxes
            .iter()
            .fold((boxes[0].0, boxes[0].1), |(lo, hi), (a, b)| {
                (lo.inf(a), hi.sup(b))
            });
        Ok(MeshSdf {
            mesh: mesh.clone(),
            bvh: Bvh::new(&boxes),
            face_normals,
            edge_normals,
            vertex_normals,
            min,
            max,
        })
    }

    /// The mesh the distances are to.
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    /// The mesh's axis-aligned bounding box, `(min, max)`.
    pub fn bounds(&self) -> (Vector, Vector) {
        (self.min, self.max)
    }

    /// Signed distance from `p` to the surface: negative inside.
    pub fn distance(&self, p: &Vector) -> Real {
        self.closest(p).distance
    }

    /// Unit gradient of the signed distance at `p` (outward normal of the
    /// level set through `p`).
    pub fn gradient(&self, p: &Vector) -> Vector {
        self.closest(p).normal
    }

    /// Closest point, signed distance and gradient at `p`.
    pub fn closest(&self, p: &Vector) -> Closest {
        let Some((triangle, _, (point, feature))) = self.bvh.nearest(p, |t| {
            let (q, feature) = closest_point_on_triangle(p, &self.mesh.corners(t as usize));
            ((q - p).norm_squared(), (q, feature))
        }) else {
            unreachable!("MeshSdf::new rejects meshes without triangles")
        };
        let triangle = triangle as usize;
        let pseudo_normal = match feature {
            Feature::Face => self.face_normals[triangle],
            Feature::Edge(k) => self.edge_normals[triangle][k as usize],
            Feature::Vertex(k) => {
                self.vertex_normals[self.mesh.triangles[triangle][k as usize] as usize]
            }
        };
        let offset = p - point;
        let outside = offset.dot(&pseudo_normal) >= 0.0;
        let length = offset.norm();
        let sign = if outside { 1.0 } else { -1.0 };
        // Within round-off of the surface the offset's direction is noise;
        // the feature's pseudo-normal is the surface's own.
        let normal = if length > 1e-12 * (self.max - self.min).norm() {
            offset * (sign / length)
        } else {
            pseudo_normal.normalize()
        };
        Closest {
            point,
            distance: sign * length,
            normal,
            triangle,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::uniform;
    use rayon::prelude::*;

    fn random_point(seed: &mut u64, half: Real) -> Vector {
        Vector::new(uniform(seed), uniform(seed), uniform(seed)).map(|x| half * (2.0 * x - 1.0))
    }

    /// Exact signed distance to the box `[-h, h]` (Quílez's formula).
    fn box_distance(p: &Vector, h: &Vector) -> Real {
        let q = p.abs() - h;
        q.sup(&Vector::zeros()).norm() + q.max().min(0.0)
    }

    /// A cuboid mesh is exact, so its signed distance matches the box's to
    /// rounding everywhere, including just off its edges and corners,
    /// where the sign comes from edge and vertex pseudo-normals.
    #[test]
    fn cuboid_distance_matches_the_exact_box() {
        let h = Vector::new(1.0, 0.5, 0.75);
        let sdf = MeshSdf::new(&TriMesh::cuboid(-h, h)).expect("closed");
        let mut seed = 3;
        for _ in 0..20_000 {
            let p = random_point(&mut seed, 2.0);
            let (d, exact) = (sdf.distance(&p), box_distance(&p, &h));
            assert!((d - exact).abs() < 1e-12, "{p:?}: {d} vs {exact}");
        }
        // Just off every corner and edge midpoint, in and out.
        for eps in [1e-3, 1e-7] {
            for corner in 0..8 {
                let s = Vector::new(
                    if corner & 1 == 0 { -1.0 } else { 1.0 },
                    if corner & 2 == 0 { -1.0 } else { 1.0 },
                    if corner & 4 == 0 { -1.0 } else { 1.0 },
                );
                let vertex = s.component_mul(&h);
                for edge_axis in [None, Some(0), Some(1), Some(2)] {
                    let mut c = vertex;
                    let mut dir = s;
                    if let Some(a) = edge_axis {
                        c[a] = 0.0;
                        dir[a] = 0.0;
                    }
                    for sign in [1.0, -1.0] {
                        let p = c + dir * (sign * eps);
                        let d = sdf.distance(&p);
                        assert_eq!(d.signum(), sign, "{p:?} off {c:?}: {d}");
                        assert!((d - box_distance(&p, &h)).abs() < 1e-12);
                    }
                }
            }
        }
    }

    /// The icosphere's faces lie between radii `R - chord` and `R`, so its
    /// signed distance is within `chord` of the sphere's everywhere, and
    /// the sign is the sphere's wherever the two agree on it.
    #[test]
    fn icosphere_distance_is_within_the_chord_error_of_the_sphere() {
        let radius = 1.3;
        let mesh = TriMesh::icosphere(Vector::zeros(), radius, 3);
        let chord = radius
            - (0..mesh.triangles.len())
                .map(|t| {
                    let [a, b, c] = mesh.corners(t);
                    (b - a).cross(&(c - a)).normalize().dot(&a).abs()
                })
                .fold(Real::INFINITY, Real::min);
        assert!(chord > 0.0 && chord < 0.02 * radius, "chord {chord}");
        let sdf = MeshSdf::new(&mesh).expect("closed");
        let mut seed = 9;
        let mut worst: Real = 0.0;
        for _ in 0..20_000 {
            let p = random_point(&mut seed, 2.0);
            let (d, exact) = (sdf.distance(&p), p.norm() - radius);
            worst = worst.max((d - exact).abs());
            assert!((d - exact).abs() <= chord + 1e-12, "{p:?}: {d} vs {exact}");
            if p.norm() < radius - chord {
                assert!(d < 0.0);
            } else if p.norm() > radius {
                assert!(d > 0.0);
            }
        }
        // The bound is attained near face centres, not loose.
        assert!(worst > 0.5 * chord, "worst {worst}, chord {chord}");
    }

    /// A star with 12 spikes: the icosphere with its original icosahedron
    /// vertices pushed out, so it has concave edges and vertices.
    fn star() -> TriMesh {
        let mut mesh = TriMesh::icosphere(Vector::zeros(), 1.0, 2);
        for v in &mut mesh.vertices[..12] {
            *v *= 1.8;
        }
        mesh
    }

    /// Where the ray from the origin along `dir` leaves the star-shaped
    /// mesh (Möller–Trumbore against every triangle).
    fn exit_radius(mesh: &TriMesh, dir: &Vector) -> Real {
        (0..mesh.triangles.len())
            .filter_map(|t| {
                let [a, b, c] = mesh.corners(t);
                let (e1, e2) = (b - a, c - a);
                let h = dir.cross(&e2);
                let det = e1.dot(&h);
                let s = -a;
                let u = s.dot(&h) / det;
                let q = s.cross(&e1);
                let v = dir.dot(&q) / det;
                let t = e2.dot(&q) / det;
                (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some(t * dir.norm())
            })
            .fold(Real::INFINITY, Real::min)
    }

    /// On a non-convex mesh the sign matches an independent inside test
    /// (the ray from the centre of the star-shaped mesh), including just
    /// off concave vertices and edges, and the distance matches a scan of
    /// every triangle.
    #[test]
    fn star_sign_matches_ray_casting_near_concave_features() {
        let mesh = star();
        assert!(mesh.is_closed());
        let sdf = MeshSdf::new(&mesh).expect("closed");
        let mut seed = 21;
        let mut points: Vec<Vector> = (0..3000).map(|_| random_point(&mut seed, 2.0)).collect();
        for v in 0..mesh.vertices.len() {
            for _ in 0..4 {
                let dir = random_point(&mut seed, 1.0).normalize();
                points.push(mesh.vertices[v] + 1e-4 * dir);
            }
        }
        for tri in &mesh.triangles {
            for k in 0..3 {
                let mid = (mesh.vertices[tri[k] as usize]
                    + mesh.vertices[tri[(k + 1) % 3] as usize])
                    / 2.0;
                let dir = random_point(&mut seed, 1.0).normalize();
                points.push(mid + 1e-4 * dir);
            }
        }
        for p in &points {
            let closest = sdf.closest(p);
            let inside = p.norm() < exit_radius(&mesh, p);
            assert_eq!(
                closest.distance < 0.0,
                inside,
                "{p:?}: {}",
                closest.distance
            );
            let scan = (0..mesh.triangles.len())
                .map(|t| (closest_point_on_triangle(p, &mesh.corners(t)).0 - p).norm())
                .fold(Real::INFINITY, Real::min);
            assert!((closest.distance.abs() - scan).abs() < 1e-12);
        }
    }

    /// The gradient is a unit vector that matches central differences of
    /// the distance, and queries agree across threads.
    #[test]
    fn gradient_matches_finite_differences_and_queries_run_in_parallel() {
        let sdf = MeshSdf::new(&star()).expect("closed");
        let mut seed = 4;
        let points: Vec<Vector> = (0..2000).map(|_| random_point(&mut seed, 2.2)).collect();
        let h = 1e-6;
        let mut checked = 0;
        for p in &points {
            let g = sdf.gradient(p);
            assert!((g.norm() - 1.0).abs() < 1e-12);
            let fd = Vector::from_fn(|a, _| {
                let e = Vector::ith(a, h);
                (sdf.distance(&(p + e)) - sdf.distance(&(p - e))) / (2.0 * h)
            });
            // Skip the medial axis, where the distance has a kink.
            if (fd.norm() - 1.0).abs() < 1e-4 {
                assert!((fd - g).norm() < 1e-4, "{p:?}: {g:?} vs {fd:?}");
                checked += 1;
            }
        }
        assert!(checked > 1900, "only {checked} points off the medial axis");
        let serial: Vec<Real> = points.iter().map(|p| sdf.distance(p)).collect();
        let parallel: Vec<Real> = points.par_iter().map(|p| sdf.distance(p)).collect();
        assert_eq!(serial, parallel);
    }

    #[test]
    fn open_flipped_and_degenerate_meshes_are_rejected() {
        let mut open = TriMesh::cuboid(Vector::zeros(), Vector::repeat(1.0));
        open.triangles.pop();
        assert!(matches!(
            MeshSdf::new(&open),
            Err(MeshError::NotClosed { boundary: 3, .. })
        ));
        let mut flipped = TriMesh::cuboid(Vector::zeros(), Vector::repeat(1.0));
        for t in &mut flipped.triangles {
            t.swap(1, 2);
        }
        let err = MeshSdf::new(&flipped).expect_err("inside out");
        assert!(matches!(err, MeshError::InsideOut { volume } if (volume + 1.0).abs() < 1e-12));
        // A tetrahedron squashed flat: its last face has collinear corners.
        let flat = TriMesh {
            vertices: vec![
                Vector::zeros(),
                Vector::x(),
                Vector::y(),
                Vector::new(0.5, 0.5, 0.0),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        };
        assert_eq!(
            MeshSdf::new(&flat).err(),
            Some(MeshError::ZeroAreaTriangle { triangle: 3 })
        );
        assert_eq!(
            MeshSdf::new(&TriMesh::default()).err(),
            Some(MeshError::Empty)
        );
    }
}
