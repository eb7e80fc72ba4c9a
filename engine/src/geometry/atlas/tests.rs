use super::*;
use crate::geometry::TriMesh;
use std::f64::consts::PI;

/// Quads around a ring, `around` of them in each of `rows` rows, each
/// split in two; the rows wrap into a tube when `wrap` (a torus), else
/// they end at two rims. `place(i, j)` places ring `i`'s vertex `j`.
fn ring_mesh(
    around: usize,
    rows: usize,
    wrap: bool,
    place: impl Fn(usize, usize) -> Vector,
) -> TriMesh {
    let per_ring = if wrap { rows } else { rows + 1 };
    let index = |i: usize, j: usize| ((i % around) * per_ring + j % per_ring) as u32;
    let vertices = (0..around)
        .flat_map(|i| (0..per_ring).map(move |j| (i, j)))
        .map(|(i, j)| place(i, j))
        .collect();
    let mut triangles = Vec::new();
    for i in 0..around {
        for j in 0..rows {
            let (a, b, c, d) = (
                index(i, j),
                index(i + 1, j),
                index(i + 1, j + 1),
                index(i, j + 1),
            );
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    TriMesh {
        vertices,
        triangles,
    }
}

/// A torus of radii `big` and `small`, `around` by `across` quads.
fn torus(big: Real, small: Real, around: usize, across: usize) -> TriMesh {
    ring_mesh(around, across, true, |i, j| {
        let theta = 2.0 * PI * i as Real / around as Real;
        let phi = 2.0 * PI * j as Real / across as Real;
        let r = big + small * phi.cos();
        Vector::new(r * theta.cos(), r * theta.sin(), small * phi.sin())
    })
}

/// An open cylinder of radius 1 and height 2 (two boundary loops).
fn tube(around: usize, along: usize) -> TriMesh {
    ring_mesh(around, along, false, |i, j| {
        let theta = 2.0 * PI * i as Real / around as Real;
        Vector::new(
            theta.cos(),
            theta.sin(),
            2.0 * j as Real / along as Real - 1.0,
        )
    })
}

/// Every vertex's point maps back onto the vertex; every chart is
/// conformal to the stated distortion and within the area bound.
fn check_cover(mesh: &TriMesh, atlas: &Atlas, angle: Real) {
    for (v, &u) in atlas.vertex_parameters().iter().enumerate() {
        let back = atlas.surface_point(u);
        assert!(
            (back - mesh.vertices[v]).norm() < 1e-9,
            "vertex {v}: {back} against {}",
            mesh.vertices[v]
        );
        assert!(atlas.distance(u) < 1e-9, "vertex {v} off its chart");
    }
    for d in atlas.distortions() {
        assert!(d.angle_mean < angle, "{d:?}");
        assert!(d.area_max / d.area_min <= 16.0, "{d:?}");
    }
}

#[test]
fn a_disk_keeps_its_single_chart() {
    let mesh = TriMesh::grid(6, 4, |i, j| {
        Vector::new(i as Real, j as Real, 0.1 * (i * j) as Real)
    });
    let chart = ConformalChart::new(&mesh).expect("a disk");
    let atlas = Atlas::new(&mesh, &AtlasParams::new(0.5)).expect("a disk");
    assert_eq!(atlas.chart_count(), 1);
    assert_eq!(atlas.vertex_parameters(), chart.uv());
    assert_eq!(atlas.bounds(), chart.bounds());
    assert!(atlas.seams().is_empty());
    assert!(atlas.transfers(chart.uv()[7]).is_empty());
    assert_eq!(atlas.boundary().len(), chart.boundary().len());
}

#[test]
fn a_sphere_is_cut_into_disks_that_meet_along_seams() {
    let mesh = TriMesh::icosphere(Vector::zeros(), 1.0, 3);
    let atlas = Atlas::new(&mesh, &AtlasParams::new(0.3)).expect("a sphere has an atlas");
    assert!(atlas.chart_count() >= 2, "{}", atlas.chart_count());
    assert!(!atlas.seams().is_empty());
    assert!(atlas.boundary().is_empty(), "a closed surface has no rim");
    // Every chart meets another, and the seams' edges are the regions'
    // shared edges: at least a great circle's worth.
    let seam_edges: usize = atlas.seams().iter().map(|s| s.edges).sum();
    assert!(seam_edges >= 20, "{seam_edges}");
    check_cover(&mesh, &atlas, 1.1);
}

/// A point near a seam has a place in the neighbouring chart: the same
/// surface point, and the Jacobian carries short steps across to first
/// order.
#[test]
fn transfers_name_the_same_surface_point_and_carry_steps_across() {
    let mesh = TriMesh::icosphere(Vector::zeros(), 1.0, 3);
    let atlas = Atlas::new(&mesh, &AtlasParams::new(0.3)).expect("a sphere has an atlas");
    let mut checked = 0;
    // Each owned triangle's centroid, so that short steps stay in it
    // (the transition is linear per triangle).
    let centroids: Vec<Point2> = atlas
        .charts
        .iter()
        .flat_map(|c| {
            (0..c.owned.triangles().len()).map(move |t| {
                let q = corners(&c.owned, t);
                [
                    (q[0][0] + q[1][0] + q[2][0]) / 3.0 + c.offset[0],
                    (q[0][1] + q[1][1] + q[2][1]) / 3.0 + c.offset[1],
                ]
            })
        })
        .collect();
    for &u in &centroids {
        for t in atlas.transfers(u) {
            let here = atlas.surface_point(u);
            // `at` lies in the other chart's band, off its own triangles:
            // read it through that chart's patch.
            let c = atlas.chart_of(t.at);
            assert_ne!(c, atlas.chart_of(u));
            let chart = &atlas.charts[c];
            let local = [t.at[0] - chart.offset[0], t.at[1] - chart.offset[1]];
            let there = chart.extended.surface_point(local);
            assert!((here - there).norm() < 1e-9, "{here} against {there}");
            let d = [1e-4, -0.5e-4];
            let step = t.jacobian * nalgebra::Vector2::new(d[0], d[1]);
            let own = atlas.surface_point([u[0] + step[0], u[1] + step[1]]);
            let other = chart
                .extended
                .surface_point([local[0] + d[0], local[1] + d[1]]);
            assert!((own - other).norm() < 1e-12, "{}", (own - other).norm());
            checked += 1;
        }
    }
    assert!(checked > 20, "only {checked} triangles near a seam");
}

#[test]
fn a_torus_is_cut_into_disks() {
    let mesh = torus(2.0, 0.7, 48, 16);
    let atlas = Atlas::new(&mesh, &AtlasParams::new(0.3)).expect("a torus has an atlas");
    assert!(atlas.chart_count() >= 3, "{}", atlas.chart_count());
    check_cover(&mesh, &atlas, 1.1);
}

#[test]
fn an_open_tube_keeps_both_rims() {
    let mesh = tube(32, 16);
    let atlas = Atlas::new(&mesh, &AtlasParams::new(0.3)).expect("a tube has an atlas");
    assert!(atlas.chart_count() >= 2);
    assert_eq!(atlas.boundary().len(), 64);
    for (edge, ends) in atlas.boundary() {
        for k in 0..2 {
            let p = atlas.surface_point(ends[k]);
            assert!((p - mesh.vertices[edge[k] as usize]).norm() < 1e-9);
        }
    }
    check_cover(&mesh, &atlas, 1.05);
}

#[test]
fn bad_input_is_refused_with_what_to_change() {
    let mesh = TriMesh::icosphere(Vector::zeros(), 1.0, 1);
    for reach in [0.0, -1.0, Real::NAN] {
        let e = Atlas::new(&mesh, &AtlasParams::new(reach)).expect_err("no reach");
        assert!(e.to_string().contains("reach"), "{e}");
    }
    let empty = TriMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    let e = Atlas::new(&empty, &AtlasParams::new(0.1)).expect_err("no triangles");
    assert!(e.to_string().contains("not a disk"), "{e}");
    // Two triangles on one edge with a third: not a manifold.
    let fan = TriMesh {
        vertices: vec![
            Vector::zeros(),
            Vector::x(),
            Vector::y(),
            Vector::z(),
            -Vector::y(),
        ],
        triangles: vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
    };
    let e = Atlas::new(&fan, &AtlasParams::new(0.1)).expect_err("three triangles on an edge");
    assert!(
        matches!(
            e,
            AtlasError::NotManifold {
                non_manifold: 1,
                ..
            }
        ),
        "{e}"
    );
    // A band wider than the sphere wraps every chart around it.
    let e = Atlas::new(&mesh, &AtlasParams::new(10.0)).expect_err("a band around the sphere");
    assert!(e.to_string().contains("coarsen"), "{e}");
}
