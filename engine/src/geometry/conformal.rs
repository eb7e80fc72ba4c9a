//! A conformal chart of a disk-topology surface patch (Guo–Qin, Section
//! 4.2): the parametric domain a thin shell's nodes live on.
//!
//! **Which map.** The least-squares conformal map (Lévy, Petitjean, Ray
//! & Maillot 2002, "Least squares conformal maps for automatic texture
//! atlas generation"): per triangle, the Cauchy–Riemann equations of the
//! map from the triangle's own plane to `(u, v)`, squared, weighted by
//! area and summed; two vertices are pinned and the rest follow from one
//! sparse symmetric positive definite solve (faer's Cholesky, over 2 x 2
//! blocks, `linalg/sparse.rs`). Why it and not a harder discrete
//! conformal map: it is linear (one factorisation, no iterations), it is
//! exact wherever a patch unfolds without stretch (planes and cylinders
//! in the tests; any developable patch), its boundary is free, so the
//! map is not forced into a disk and stays close to conformal on curved
//! patches, and what it does not get exactly is measured per chart (the
//! distortion below), so a chart that is too curved is seen and cut
//! smaller.
//!
//! With a triangle's corners at `(x_k, y_k)` in its own orthonormal frame,
//! area `A`, and `W_k = (x_{k+2} - x_{k+1}) + i (y_{k+2} - y_{k+1})`, the
//! map `U = u + i v` is conformal on it when `sum_k W_k U_k = 0`; the
//! energy is `sum_T |sum_k W_k U_k|^2 / (2 A_T)`. Each triangle adds to
//! the normal equations, for its corners `j, k`, the block
//! `[[c, s], [-s, c]]` over `(u_j, v_j) x (u_k, v_k)` with
//! `c = a_j a_k + b_j b_k`, `s = b_j a_k - a_j b_k` and `a + i b = W /
//! sqrt(2 A)`.
//!
//! **Distortion.** Per triangle the map's Jacobian from the surface to the
//! plane has singular values `s1 >= s2`: `s1 / s2` is its angle distortion
//! (1 where it is conformal) and `lambda = 1 / sqrt(s1 s2)` the conformal
//! factor (surface length over parametric length), whose square is the
//! area element the mechanics integrate with. A vertex's `lambda` is the
//! area-weighted mean of its triangles'. The pins are the two vertices
//! farthest apart (found in two sweeps), placed their surface distance
//! apart, so `lambda` is about one where the map keeps lengths.

use super::TriMesh;
use super::closest_point_on_triangle;
use super::quadtree::{ChartDomain, Point2};
use crate::linalg::sparse::{BlockPattern, SparseCholesky};
use crate::math::{Real, Vector};
use grid::ChartGrid;

/// Why a patch could not be charted. Each message says what to change.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChartError {
    /// The patch is not a disk: it has no boundary (a closed surface), a
    /// non-manifold or misoriented edge, holes or several pieces.
    #[error(
        "the patch is not a disk (Euler characteristic {euler}, {boundary} boundary edges, \
         {non_manifold} non-manifold and {misoriented} misoriented edges); cut the surface \
         into disk-like charts"
    )]
    NotDisk {
        /// `V - E + F` (1 for a disk).
        euler: i64,
        /// Edges on one triangle.
        boundary: usize,
        /// Edges on three or more triangles.
        non_manifold: usize,
        /// Edges two triangles traverse the same way.
        misoriented: usize,
    },
    /// A triangle has no area or a non-finite corner.
    #[error("triangle {triangle} is degenerate (zero area or a non-finite corner); remove it")]
    Degenerate {
        /// Its index.
        triangle: usize,
    },
    /// The normal equations could not be factorised.
    #[error(
        "the conformal map's equations are singular ({unknowns} unknowns); the patch may be \
         in several pieces: chart each piece"
    )]
    Singular {
        /// Unknowns of the solve.
        unknowns: usize,
    },
    /// The map folds: a triangle turns over in the plane.
    #[error(
        "the conformal map turns {flipped} triangles over (the patch is too curved for one \
         chart); cut it into smaller charts"
    )]
    Folded {
        /// Triangles with negative area in the plane.
        flipped: usize,
    },
}

/// How far a chart is from conformal and from keeping areas.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Distortion {
    /// Largest angle distortion `s1 / s2` over the triangles (1:
    /// conformal).
    pub angle_max: Real,
    /// Its area-weighted mean.
    pub angle_mean: Real,
    /// Smallest and largest `lambda^2` over the triangles, over its
    /// area-weighted mean: the area distortion the quadtree's grading
    /// takes up.
    pub area_min: Real,
    /// See `area_min`.
    pub area_max: Real,
}

/// A disk-topology patch mapped conformally to the plane.
#[derive(Debug, Clone)]
pub struct ConformalChart {
    uv: Vec<Point2>,
    triangles: Vec<[u32; 3]>,
    lambda_vertices: Vec<Real>,
    distortion: Distortion,
    boundary: Vec<[u32; 2]>,
    /// The patch's vertices on the surface.
    positions: Vec<Vector>,
    grid: ChartGrid,
    lo: Point2,
    hi: Point2,
}

impl ConformalChart {
    /// The least-squares conformal map of `mesh` (see the module's
    /// documentation).
    ///
    /// # Errors
    /// [`ChartError`]: a patch that is not a disk, a degenerate triangle,
    /// a singular system, or a map that folds.
    pub fn new(mesh: &TriMesh) -> Result<Self, ChartError> {
        let n = mesh.vertices.len();
        let report = mesh.edge_report();
        let euler = n as i64 - report.edges as i64 + mesh.triangles.len() as i64;
        if euler != 1 || report.boundary == 0 || report.non_manifold > 0 || report.misoriented > 0 {
            return Err(ChartError::NotDisk {
                euler,
                boundary: report.boundary,
                non_manifold: report.non_manifold,
                misoriented: report.misoriented,
            });
        }
        // Each triangle's W / sqrt(2 A), as (a, b) per corner.
        let mut coefficients = Vec::with_capacity(mesh.triangles.len());
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let (area, local) = local_frame(tri.map(|k| mesh.vertices[k as usize]));
            if !(area.is_finite() && area > 0.0) {
                return Err(ChartError::Degenerate { triangle: t });
            }
            let scale = 1.0 / (2.0 * area).sqrt();
            let mut ab = [[0.0; 2]; 3];
            for k in 0..3 {
                let (next, after) = (local[(k + 1) % 3], local[(k + 2) % 3]);
                ab[k] = [(after[0] - next[0]) * scale, (after[1] - next[1]) * scale];
            }
            coefficients.push(ab);
        }
        let (first, second) = farthest_pair(&mesh.vertices);
        let pins = [
            (first, [0.0, 0.0]),
            (
                second,
                [(mesh.vertices[second] - mesh.vertices[first]).norm(), 0.0],
            ),
        ];
        // Free vertices, numbered in vertex order.
        let mut free = vec![u32::MAX; n];
        let mut count = 0u32;
        for (v, slot) in free.iter_mut().enumerate() {
            if v != first && v != second {
                *slot = count;
                count += 1;
            }
        }
        let unknowns = 2 * count as usize;
        let mut around: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for &k in tri {
                around[k as usize].push(t as u32);
            }
        }
        let mut by_free = vec![0usize; count as usize];
        for (v, &f) in free.iter().enumerate() {
            if f != u32::MAX {
                by_free[f as usize] = v;
            }
        }
        let columns: Vec<Vec<u32>> = by_free
            .iter()
            .map(|&v| {
                let mut rows: Vec<u32> = around[v]
                    .iter()
                    .flat_map(|&t| mesh.triangles[t as usize])
                    .map(|k| free[k as usize])
                    .filter(|&f| f != u32::MAX && f >= free[v])
                    .collect();
                rows.sort_unstable();
                rows.dedup();
                rows
            })
            .collect();
        let pattern = BlockPattern::new(2, &columns).ok_or(ChartError::Singular { unknowns })?;
        // The 2 x 2 block of corners j, k of triangle t, row j.
        let block = |t: usize, j: usize, k: usize| {
            let [aj, bj] = coefficients[t][j];
            let [ak, bk] = coefficients[t][k];
            (aj * ak + bj * bk, bj * ak - aj * bk)
        };
        let column = |c: usize, out: &mut crate::linalg::sparse::BlockColumn<'_>| {
            let v = by_free[c];
            for &t in &around[v] {
                let tri = mesh.triangles[t as usize];
                let k = tri.iter().position(|&x| x as usize == v).unwrap_or(0);
                for (j, &m) in tri.iter().enumerate() {
                    let row = free[m as usize];
                    let Some(slot) = (row != u32::MAX).then(|| out.slot(row)).flatten() else {
                        continue;
                    };
                    let (cc, s) = block(t as usize, j, k);
                    out.add(slot, 0, 0, cc);
                    out.add(slot, 1, 0, s);
                    out.add(slot, 0, 1, -s);
                    out.add(slot, 1, 1, cc);
                }
            }
        };
        let mut rhs = vec![0.0; unknowns];
        for &(p, at) in &pins {
            for &t in &around[p] {
                let tri = mesh.triangles[t as usize];
                let k = tri.iter().position(|&x| x as usize == p).unwrap_or(0);
                for (j, &m) in tri.iter().enumerate() {
                    let row = free[m as usize];
                    if row == u32::MAX {
                        continue;
                    }
                    let (cc, s) = block(t as usize, j, k);
                    rhs[2 * row as usize] -= cc * at[0] + s * at[1];
                    rhs[2 * row as usize + 1] -= -s * at[0] + cc * at[1];
                }
            }
        }
        let mut solver = SparseCholesky::default();
        let solution = solver
            .solve(&pattern, column, rhs)
            .ok_or(ChartError::Singular { unknowns })?;
        let mut uv = vec![[0.0; 2]; n];
        for (v, &f) in free.iter().enumerate() {
            if f != u32::MAX {
                uv[v] = [solution[2 * f as usize], solution[2 * f as usize + 1]];
            }
        }
        for &(p, at) in &pins {
            uv[p] = at;
        }
        Self::measure(mesh, uv)
    }

    /// A chart of `mesh` with the parametric positions `uv` given (one
    /// per vertex), measured as [`Self::new`] measures its own map: a
    /// patch of a map made over a larger patch (an atlas's chart).
    ///
    /// # Errors
    /// [`ChartError::Folded`] where a triangle turns over, and
    /// [`ChartError::Singular`] when `uv` does not hold one point per
    /// vertex.
    pub(crate) fn with_map(mesh: &TriMesh, uv: Vec<Point2>) -> Result<Self, ChartError> {
        if uv.len() != mesh.vertices.len() {
            return Err(ChartError::Singular { unknowns: uv.len() });
        }
        Self::measure(mesh, uv)
    }

    /// The patch's triangles, as vertex indices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The parametric position of each vertex.
    pub fn uv(&self) -> &[Point2] {
        &self.uv
    }

    /// Each vertex's conformal factor (area-weighted over its triangles).
    pub fn lambda_vertices(&self) -> &[Real] {
        &self.lambda_vertices
    }

    /// How far from conformal and from area-keeping the chart is.
    pub fn distortion(&self) -> Distortion {
        self.distortion
    }

    /// The box of the parametric positions.
    pub fn bounds(&self) -> (Point2, Point2) {
        (self.lo, self.hi)
    }

    /// The patch's boundary edges, as vertex pairs.
    pub fn boundary(&self) -> &[[u32; 2]] {
        &self.boundary
    }

    /// The triangle holding `u` and `u`'s barycentric weights in it.
    pub fn locate(&self, u: Point2) -> Option<(usize, [Real; 3])> {
        self.grid.triangles_at(u).iter().find_map(|&t| {
            let tri = self.triangles[t as usize];
            let [a, b, c] = tri.map(|k| self.uv[k as usize]);
            barycentric(u, a, b, c).map(|w| (t as usize, w))
        })
    }

    /// The parametric position of the patch's point nearest to `p`, and
    /// its distance from `p`: the inverse of [`Self::surface_point`] for
    /// a point on the patch. A search over every triangle, for a
    /// user's pick (a grab), not for inner loops.
    pub fn parameter_of(&self, p: &Vector) -> Option<(Point2, Real)> {
        let (t, q, d) = self
            .triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let corners = tri.map(|k| self.positions[k as usize]);
                let (q, _) = closest_point_on_triangle(p, &corners);
                (t, q, (q - p).norm())
            })
            .min_by(|a, b| a.2.total_cmp(&b.2))?;
        let tri = self.triangles[t].map(|k| k as usize);
        let [a, b, c] = tri.map(|k| self.positions[k]);
        // q's barycentric weights, from the triangle's own frame.
        let (e0, e1, e2) = (b - a, c - a, q - a);
        let (d00, d01, d11) = (e0.dot(&e0), e0.dot(&e1), e1.dot(&e1));
        let (d20, d21) = (e2.dot(&e0), e2.dot(&e1));
        let det = d00 * d11 - d01 * d01;
        if det <= 0.0 {
            return None;
        }
        let wb = (d11 * d20 - d01 * d21) / det;
        let wc = (d00 * d21 - d01 * d20) / det;
        let wa = 1.0 - wb - wc;
        let [ua, ub, uc] = tri.map(|k| self.uv[k]);
        Some((
            [
                wa * ua[0] + wb * ub[0] + wc * uc[0],
                wa * ua[1] + wb * ub[1] + wc * uc[1],
            ],
            d,
        ))
    }

    /// The point of the surface patch at `u`: interpolated in the
    /// triangle holding it, or at the nearest point of the boundary for a
    /// point just outside (a Gauss point on the boundary, rounded).
    pub fn surface_point(&self, u: Point2) -> Vector {
        if let Some((t, w)) = self.locate(u) {
            let tri = self.triangles[t];
            return (0..3).map(|k| w[k] * self.positions[tri[k] as usize]).sum();
        }
        let edge = match self.grid.nearest_edge(u, |e| self.edge_distance(u, e)) {
            Ok((e, _)) => e,
            Err(_) => (0..self.boundary.len() as u32)
                .min_by(|&a, &b| {
                    self.edge_distance(u, a)
                        .total_cmp(&self.edge_distance(u, b))
                })
                .unwrap_or(0),
        };
        let Some(&[a, b]) = self.boundary.get(edge as usize) else {
            return Vector::zeros();
        };
        let t = segment_parameter(u, self.uv[a as usize], self.uv[b as usize]);
        (1.0 - t) * self.positions[a as usize] + t * self.positions[b as usize]
    }

    fn edge_distance(&self, u: Point2, e: u32) -> Real {
        let [a, b] = self.boundary[e as usize];
        segment_distance(u, self.uv[a as usize], self.uv[b as usize])
    }

    fn measure(mesh: &TriMesh, uv: Vec<Point2>) -> Result<Self, ChartError> {
        let n = mesh.vertices.len();
        let (mut angle_max, mut angle_sum, mut area_sum) = (1.0 as Real, 0.0, 0.0);
        let mut flipped = 0;
        let mut lambda_sum = vec![0.0; n];
        let mut weight_sum = vec![0.0; n];
        let mut squares = Vec::with_capacity(mesh.triangles.len());
        for tri in &mesh.triangles {
            let (area, [_, l1, l2]) = local_frame(tri.map(|k| mesh.vertices[k as usize]));
            let [q0, q1, q2] = tri.map(|k| uv[k as usize]);
            // Surface (local 2D) -> plane: J S = Q, S and Q the edge
            // matrices.
            let s = nalgebra::Matrix2::new(l1[0], l2[0], l1[1], l2[1]);
            let q =
                nalgebra::Matrix2::new(q1[0] - q0[0], q2[0] - q0[0], q1[1] - q0[1], q2[1] - q0[1]);
            let plane_area = 0.5 * q.determinant();
            if plane_area <= 0.0 {
                flipped += 1;
                continue;
            }
            let j = q * s.try_inverse().unwrap_or_else(nalgebra::Matrix2::zeros);
            let sv = j.singular_values();
            let (s1, s2) = (sv[0].max(sv[1]), sv[0].min(sv[1]));
            let angle = s1 / s2;
            let lambda = 1.0 / (s1 * s2).sqrt();
            angle_max = angle_max.max(angle);
            angle_sum += angle * area;
            area_sum += area;
            squares.push((lambda * lambda, area));
            for &k in tri {
                lambda_sum[k as usize] += lambda * area;
                weight_sum[k as usize] += area;
            }
        }
        if flipped > 0 {
            return Err(ChartError::Folded { flipped });
        }
        let mean_square = squares.iter().map(|(l, a)| l * a).sum::<Real>() / area_sum;
        let (area_min, area_max) = squares
            .iter()
            .fold((Real::INFINITY, 0.0 as Real), |(lo, hi), (l, _)| {
                (lo.min(l / mean_square), hi.max(l / mean_square))
            });
        let lambda_vertices = lambda_sum
            .iter()
            .zip(&weight_sum)
            .map(|(l, w)| if *w > 0.0 { l / w } else { 1.0 })
            .collect();
        let mut lo = [Real::INFINITY; 2];
        let mut hi = [Real::NEG_INFINITY; 2];
        for p in &uv {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let boundary = boundary_edges(&mesh.triangles);
        Ok(Self {
            grid: ChartGrid::new(&uv, &mesh.triangles, &boundary),
            boundary,
            positions: mesh.vertices.clone(),
            triangles: mesh.triangles.clone(),
            uv,
            lambda_vertices,
            distortion: Distortion {
                angle_max,
                angle_mean: angle_sum / area_sum,
                area_min,
                area_max,
            },
            lo,
            hi,
        })
    }
}

/// The chart's domain is its triangles' image: the distance to the image
/// of the boundary edges, negative inside a triangle; `lambda`
/// interpolated in the triangle holding a point, or the nearest boundary
/// vertex's outside. Both read the chart's grid, a few cells per query.
impl ChartDomain for ConformalChart {
    fn distance(&self, u: Point2) -> Real {
        let nearest = match self.grid.nearest_edge(u, |e| self.edge_distance(u, e)) {
            Ok((_, d)) | Err(d) => d,
        };
        if self.locate(u).is_some() {
            -nearest
        } else {
            nearest
        }
    }

    /// Inside where a triangle holds the point, as the distance's sign
    /// says, without the search for the nearest boundary edge.
    fn contains(&self, u: Point2) -> bool {
        self.locate(u).is_some()
    }

    fn lambda(&self, u: Point2) -> Real {
        if let Some((t, w)) = self.locate(u) {
            let tri = self.triangles[t];
            return (0..3)
                .map(|k| w[k] * self.lambda_vertices[tri[k] as usize])
                .sum();
        }
        match self.grid.nearest_edge(u, |e| self.edge_distance(u, e)) {
            Ok((e, _)) => {
                let [a, b] = self.boundary[e as usize];
                let t = segment_parameter(u, self.uv[a as usize], self.uv[b as usize]);
                (1.0 - t) * self.lambda_vertices[a as usize] + t * self.lambda_vertices[b as usize]
            }
            // Far outside: any boundary value continues it.
            Err(_) => self
                .boundary
                .first()
                .map_or(1.0, |e| self.lambda_vertices[e[0] as usize]),
        }
    }
}

/// A triangle's area and its corners in its own orthonormal frame: the
/// first at the origin, the second on the x axis, the third above it.
fn local_frame([p0, p1, p2]: [Vector; 3]) -> (Real, [Point2; 3]) {
    let (e1, e2) = (p1 - p0, p2 - p0);
    let normal = e1.cross(&e2);
    let x_axis = e1.normalize();
    let y_axis = normal.normalize().cross(&x_axis);
    (
        0.5 * normal.norm(),
        [
            [0.0, 0.0],
            [e1.norm(), 0.0],
            [e2.dot(&x_axis), e2.dot(&y_axis)],
        ],
    )
}

/// The vertices farthest apart, approximately: the farthest from vertex
/// 0, then the farthest from that one.
fn farthest_pair(vertices: &[Vector]) -> (usize, usize) {
    let farthest = |from: usize| {
        (0..vertices.len())
            .max_by(|&a, &b| {
                (vertices[a] - vertices[from])
                    .norm()
                    .total_cmp(&(vertices[b] - vertices[from]).norm())
            })
            .unwrap_or(0)
    };
    let first = farthest(0);
    (first, farthest(first))
}

/// Edges on exactly one triangle.
fn boundary_edges(triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = triangles
        .iter()
        .flat_map(|t| {
            (0..3).map(move |k| {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                [a.min(b), a.max(b)]
            })
        })
        .collect();
    edges.sort_unstable();
    let mut out = Vec::new();
    let mut k = 0;
    while k < edges.len() {
        let mut end = k + 1;
        while end < edges.len() && edges[end] == edges[k] {
            end += 1;
        }
        if end - k == 1 {
            out.push(edges[k]);
        }
        k = end;
    }
    out
}

fn segment_distance(u: Point2, p: Point2, q: Point2) -> Real {
    let t = segment_parameter(u, p, q);
    let d = [q[0] - p[0], q[1] - p[1]];
    ((u[0] - p[0] - t * d[0]).powi(2) + (u[1] - p[1] - t * d[1]).powi(2)).sqrt()
}

/// Where on the segment `p q` the point nearest `u` lies, 0 at `p` and 1
/// at `q`.
fn segment_parameter(u: Point2, p: Point2, q: Point2) -> Real {
    let d = [q[0] - p[0], q[1] - p[1]];
    let length = d[0] * d[0] + d[1] * d[1];
    if length > 0.0 {
        (((u[0] - p[0]) * d[0] + (u[1] - p[1]) * d[1]) / length).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Barycentric weights of `u` in the triangle `a b c`, if it lies inside
/// (or on an edge).
fn barycentric(u: Point2, a: Point2, b: Point2, c: Point2) -> Option<[Real; 3]> {
    let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
    if det == 0.0 {
        return None;
    }
    let wb = ((u[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (u[1] - a[1])) / det;
    let wc = ((b[0] - a[0]) * (u[1] - a[1]) - (u[0] - a[0]) * (b[1] - a[1])) / det;
    let wa = 1.0 - wb - wc;
    let e = -1e-12;
    (wa >= e && wb >= e && wc >= e).then_some([wa, wb, wc])
}

mod grid;
#[cfg(test)]
mod tests;
