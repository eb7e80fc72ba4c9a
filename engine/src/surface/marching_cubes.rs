//! Marching cubes (Lorensen & Cline, "Marching cubes: a high resolution
//! 3D surface construction algorithm", SIGGRAPH 1987): the isosurface of a
//! scalar field sampled on a regular grid, one polygon set per grid cell,
//! looked up by which of the cell's eight corners lie inside.
//!
//! The 256-case table is not copied: it is derived at first use. For a
//! corner configuration, each of the cube's six faces is a marching square
//! whose edge crossings are joined into segments; the segments of all faces
//! chain into closed loops around the cube, and each loop is fanned into
//! triangles. Three rules make the result watertight and oriented:
//!
//! - A face with four crossings (inside corners on one diagonal, the
//!   ambiguous face Dürst pointed out in 1988 against the original table)
//!   is always resolved by separating its inside corners. The rule depends
//!   only on the face's own corner values, so the two cells that share the
//!   face cut it into the same segments, and no holes open between them.
//! - Walking a face counter-clockwise about its outward normal, each
//!   segment runs from an outside-to-inside crossing to the next crossing.
//!   That puts the inside on the right of every segment seen from outside
//!   the cube, so every loop, fanned in its tracing order, has its normal
//!   pointing from the inside (field above the iso value) to the outside.
//! - Each loop is fanned from a crossing whose diagonals all pass through
//!   the cube's interior. A diagonal joining two crossings of one face
//!   (possible on an ambiguous face) could be drawn by the neighbouring
//!   cell too, and its edge would then belong to four triangles.
//!
//! A grid edge with a crossing gets one vertex, shared by the four cells
//! around it, so the mesh is indexed and closed wherever the field is below
//! the iso value on the border of the grid.

use super::field::NodeGrid;
use crate::geometry::TriMesh;
use crate::math::Vector;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Corner `c` of a cell sits at offset `(c & 1, (c >> 1) & 1, (c >> 2) & 1)`.
fn corner_offset(c: usize) -> [usize; 3] {
    [c & 1, (c >> 1) & 1, (c >> 2) & 1]
}

/// The two axes after `axis`, in cyclic (right-handed) order.
fn other_axes(axis: usize) -> (usize, usize) {
    ((axis + 1) % 3, (axis + 2) % 3)
}

/// Cube edge `e` runs along axis `e / 4`; bit 0 of `e % 4` is the
/// coordinate on the next axis, bit 1 on the one after. Returns its lower
/// corner and its axis.
fn edge_start(e: usize) -> (usize, usize) {
    let axis = e / 4;
    let (b, c) = other_axes(axis);
    ((e & 1) << b | ((e >> 1) & 1) << c, axis)
}

/// The cube edge between corners `p` and `q`, which differ in one bit.
fn edge_between(p: usize, q: usize) -> usize {
    let axis = (p ^ q).trailing_zeros() as usize;
    let (b, c) = other_axes(axis);
    4 * axis + ((p >> b) & 1) + 2 * ((p >> c) & 1)
}

/// The six faces, each as its four corners counter-clockwise about its
/// outward normal.
fn faces() -> [[usize; 4]; 6] {
    let mut faces = [[0; 4]; 6];
    for axis in 0..3 {
        let (b, c) = other_axes(axis);
        for side in 0..2 {
            // (e_b, e_c, e_axis) is right-handed, so this order is
            // counter-clockwise about +e_axis; the face at side 0 looks
            // along -e_axis and takes it reversed.
            let mut ring =
                [(0, 0), (1, 0), (1, 1), (0, 1)].map(|(u, v)| side << axis | u << b | v << c);
            if side == 0 {
                ring.reverse();
            }
            faces[2 * axis + side] = ring;
        }
    }
    faces
}

/// The loops of edge crossings of one corner configuration, each in the
/// order that faces its fan outward: bit `c` of `case` set means corner
/// `c` is inside.
fn case_loops(case: usize) -> Vec<Vec<u8>> {
    let inside = |c: usize| (case >> c) & 1 == 1;
    // next[e]: the crossing that follows crossing `e` in its loop.
    let mut next = [usize::MAX; 12];
    for ring in faces() {
        let crossing = |k: usize| inside(ring[k]) != inside(ring[(k + 1) % 4]);
        for k in 0..4 {
            if crossing(k) && inside(ring[(k + 1) % 4]) {
                let to = (1..4)
                    .map(|step| (k + step) % 4)
                    .find(|&m| crossing(m))
                    .unwrap_or(k);
                next[edge_between(ring[k], ring[(k + 1) % 4])] =
                    edge_between(ring[to], ring[(to + 1) % 4]);
            }
        }
    }
    let mut loops = Vec::new();
    let mut visited = [false; 12];
    for start in 0..12 {
        if next[start] == usize::MAX || visited[start] {
            continue;
        }
        let mut ring = Vec::with_capacity(12);
        let mut e = start;
        while !visited[e] {
            visited[e] = true;
            ring.push(e as u8);
            e = next[e];
        }
        loops.push(ring);
    }
    loops
}

/// Whether cube edges `a` and `b` lie on a common face.
fn share_a_face(a: usize, b: usize) -> bool {
    let corners = |e: usize| {
        let (c, axis) = edge_start(e);
        [c, c | 1 << axis]
    };
    let [a0, a1] = corners(a);
    let [b0, b1] = corners(b);
    // A face is the set of corners with one bit fixed: both edges lie on
    // one when all four corners agree in some bit.
    (0..3).any(|bit| {
        let side = (a0 >> bit) & 1;
        [a1, b0, b1].iter().all(|&c| (c >> bit) & 1 == side)
    })
}

/// Triangles (as cube edges) of one corner configuration, each loop fanned
/// from the first crossing whose diagonals all cross the cube's interior.
/// A diagonal between two crossings on one face would be shared with the
/// neighbouring cell, which may draw the same diagonal: two crossings on
/// an ambiguous face that the face does not join. Every loop of the 256
/// cases has such an apex (the tests check it).
fn case_triangles(case: usize) -> Vec<[u8; 3]> {
    let mut triangles = Vec::new();
    for ring in case_loops(case) {
        let n = ring.len();
        let interior = |apex: usize| {
            (2..n.saturating_sub(1))
                .all(|d| !share_a_face(usize::from(ring[apex]), usize::from(ring[(apex + d) % n])))
        };
        let apex = (0..n).find(|&apex| interior(apex)).unwrap_or(0);
        for i in 1..n.saturating_sub(1) {
            triangles.push([ring[apex], ring[(apex + i) % n], ring[(apex + i + 1) % n]]);
        }
    }
    triangles
}

/// The triangles of all 256 configurations, derived once.
fn table() -> &'static [Vec<[u8; 3]>] {
    static TABLE: OnceLock<Vec<Vec<[u8; 3]>>> = OnceLock::new();
    TABLE.get_or_init(|| (0..256).map(case_triangles).collect())
}

/// The mesh of the surface `value = iso` of `grid`, outward normals facing
/// lower values. Corners strictly above `iso` are inside. Runs in parallel
/// over the planes of the grid; the result does not depend on the thread
/// count.
pub(crate) fn extract(grid: &NodeGrid, iso: f32) -> TriMesh {
    let [nx, ny, nz] = grid.dims;
    if nx < 2 || ny < 2 || nz < 2 {
        return TriMesh::default();
    }
    let plane = nx * ny;
    let node = |i: usize, j: usize, k: usize| i + nx * (j + ny * k);
    let inside = |n: usize| grid.values[n] > iso;

    // One vertex per grid edge with a crossing, keyed `3 * node + axis` by
    // the edge's lower node; each plane of nodes lists its own in key order.
    let per_plane: Vec<(Vec<usize>, Vec<Vector>)> = (0..nz)
        .into_par_iter()
        .map(|k| {
            let (mut keys, mut points) = (Vec::new(), Vec::new());
            for j in 0..ny {
                for i in 0..nx {
                    let n = node(i, j, k);
                    let steps = [(i + 1 < nx, 1), (j + 1 < ny, nx), (k + 1 < nz, plane)];
                    for (axis, &(exists, stride)) in steps.iter().enumerate() {
                        if exists && inside(n) != inside(n + stride) {
                            let (v0, v1) = (grid.values[n], grid.values[n + stride]);
                            let t = f64::from((iso - v0) / (v1 - v0));
                            let mut p = grid.position(i, j, k);
                            p[axis] += t * grid.cell;
                            keys.push(3 * n + axis);
                            points.push(p);
                        }
                    }
                }
            }
            (keys, points)
        })
        .collect();
    let mut first = Vec::with_capacity(nz + 1);
    first.push(0usize);
    for (keys, _) in &per_plane {
        first.push(first[first.len() - 1] + keys.len());
    }
    let vertex = |key: usize| -> u32 {
        let k = key / 3 / plane;
        let keys = &per_plane[k].0;
        // Every crossing a cell asks for was recorded by the vertex pass,
        // which applies the same inside test to the same values.
        let at = keys.binary_search(&key).unwrap_or_else(|missing| missing);
        (first[k] + at) as u32
    };

    let table = table();
    let triangles: Vec<Vec<[u32; 3]>> = (0..nz - 1)
        .into_par_iter()
        .map(|k| {
            let mut triangles = Vec::new();
            for j in 0..ny - 1 {
                for i in 0..nx - 1 {
                    let corner = |c: usize| {
                        let [di, dj, dk] = corner_offset(c);
                        node(i + di, j + dj, k + dk)
                    };
                    let case = (0..8).fold(0, |case, c| case | usize::from(inside(corner(c))) << c);
                    for tri in &table[case] {
                        triangles.push(tri.map(|e| {
                            let (c, axis) = edge_start(usize::from(e));
                            vertex(3 * corner(c) + axis)
                        }));
                    }
                }
            }
            triangles
        })
        .collect();

    TriMesh {
        vertices: per_plane
            .into_iter()
            .flat_map(|(_, points)| points)
            .collect(),
        triangles: triangles.into_iter().flatten().collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Edge numbering and lookup agree for all twelve edges.
    #[test]
    fn edges_round_trip() {
        for e in 0..12 {
            let (c, axis) = edge_start(e);
            assert_eq!(edge_between(c, c | 1 << axis), e);
            assert_eq!(edge_between(c | 1 << axis, c), e);
        }
    }

    /// Lorensen & Cline's two base cases: one corner inside cuts it off
    /// with one triangle facing away from it; a face's two corners inside
    /// give a quad (two triangles). The complement flips the normals.
    #[test]
    fn base_cases_have_the_expected_triangles() {
        let normal = |tri: &[u8; 3]| {
            let mid = |e: u8| {
                let (c, axis) = edge_start(usize::from(e));
                let mut p = Vector::from(corner_offset(c).map(|x| x as f64));
                p[axis] += 0.5;
                p
            };
            let [a, b, c] = tri.map(mid);
            (b - a).cross(&(c - a))
        };
        let one = case_triangles(1);
        assert_eq!(one.len(), 1);
        assert!(
            normal(&one[0]).iter().all(|&n| n > 0.0),
            "{:?}",
            normal(&one[0])
        );
        let rest = case_triangles(255 - 1);
        assert_eq!(rest.len(), 1);
        assert!(normal(&rest[0]).iter().all(|&n| n < 0.0));
        // Corners 0 and 1 (the bottom x-edge) inside: a quad facing +y +z.
        let two = case_triangles(0b11);
        assert_eq!(two.len(), 2);
        for tri in &two {
            let n = normal(tri);
            assert!(n.x.abs() < 1e-12 && n.y > 0.0 && n.z > 0.0, "{n:?}");
        }
        assert!(case_triangles(0).is_empty() && case_triangles(255).is_empty());
    }

    /// Every loop of every case has a fan apex whose diagonals stay inside
    /// the cube, so no diagonal can be drawn twice by two cells.
    #[test]
    fn every_loop_fans_through_the_interior() {
        for case in 0..256 {
            for ring in case_loops(case) {
                let n = ring.len();
                assert!(
                    (0..n).any(|apex| (2..n - 1).all(|d| !share_a_face(
                        usize::from(ring[apex]),
                        usize::from(ring[(apex + d) % n])
                    ))),
                    "case {case:08b}, loop {ring:?}"
                );
            }
        }
        // Two edges of one face, and two that only share the interior.
        assert!(share_a_face(edge_between(0, 1), edge_between(2, 3)));
        assert!(!share_a_face(edge_between(0, 1), edge_between(6, 7)));
    }

    /// Every loop closes: in every case each crossing edge appears in the
    /// triangles, and a fan of loops over `m` crossings has `m - 2 * loops`
    /// triangles.
    #[test]
    fn every_case_uses_each_crossing() {
        for case in 0..256 {
            let inside = |c: usize| (case >> c) & 1 == 1;
            let crossings: Vec<usize> = (0..12)
                .filter(|&e| {
                    let (c, axis) = edge_start(e);
                    inside(c) != inside(c | 1 << axis)
                })
                .collect();
            let tris = case_triangles(case);
            for &e in &crossings {
                assert!(
                    tris.iter().any(|t| t.contains(&(e as u8))),
                    "case {case:08b}: crossing {e} unused"
                );
            }
            if !crossings.is_empty() {
                let twice_loops = crossings.len() - tris.len();
                assert!(
                    twice_loops >= 2 && twice_loops.is_multiple_of(2),
                    "case {case:08b}"
                );
            }
        }
    }
}
