use super::*;
use crate::cancel::Cancel;
use crate::geometry::quadtree::{Quadtree, QuadtreeParams};

/// A grid of `nx x ny` quads over `[0, 1]^2`, each split in two
/// counter-clockwise, mapped to 3D by `place`; interior vertices are moved
/// in the parameter plane by up to `jitter` of a cell (a fixed hash).
fn grid(nx: usize, ny: usize, jitter: Real, place: impl Fn(Real, Real) -> Vector) -> TriMesh {
    TriMesh::grid(nx, ny, |i, j| {
        let (mut s, mut t) = (i as Real / nx as Real, j as Real / ny as Real);
        if i > 0 && i < nx && j > 0 && j < ny {
            let h = ((i * 7919 + j * 104_729) % 1000) as Real / 1000.0 - 0.5;
            let g = ((i * 104_729 + j * 7919) % 997) as Real / 997.0 - 0.5;
            s += jitter * h / nx as Real;
            t += jitter * g / ny as Real;
        }
        place(s, t)
    })
}

/// A tilted plane maps by a similarity: no angle or area distortion,
/// every length kept (the pins are their surface distance apart).
#[test]
fn a_plane_maps_by_a_similarity() {
    let (a, b) = (Vector::new(0.8, 0.1, 0.3), Vector::new(-0.2, 0.5, 0.9));
    let mesh = grid(10, 7, 0.6, |s, t| {
        Vector::new(1.0, 2.0, 3.0) + a * s + b * t
    });
    let chart = ConformalChart::new(&mesh).expect("a chart");
    let d = chart.distortion();
    assert!(d.angle_max - 1.0 < 1e-9, "{d:?}");
    assert!(d.area_max - 1.0 < 1e-9 && 1.0 - d.area_min < 1e-9, "{d:?}");
    for (k, lambda) in chart.lambda_vertices().iter().enumerate() {
        assert!((lambda - 1.0).abs() < 1e-9, "vertex {k}: {lambda}");
    }
    let uv = chart.uv();
    for (p, q) in [(0usize, 50usize), (3, 80), (17, 60)] {
        let flat = ((uv[p][0] - uv[q][0]).powi(2) + (uv[p][1] - uv[q][1]).powi(2)).sqrt();
        let space = (mesh.vertices[p] - mesh.vertices[q]).norm();
        assert!(
            (flat / space - 1.0).abs() < 1e-9,
            "{p}-{q}: {flat} against {space}"
        );
    }
}

/// A triangulated cylinder patch unfolds without stretch (its quads are
/// planar and meet flat at every vertex): the map is exactly conformal
/// and the factor uniform, as developability says.
#[test]
fn a_cylinder_patch_unfolds_without_distortion() {
    let mesh = grid(16, 6, 0.0, |s, t| {
        let angle = 1.5 * s;
        Vector::new(angle.cos(), angle.sin(), t)
    });
    let chart = ConformalChart::new(&mesh).expect("a chart");
    let d = chart.distortion();
    assert!(d.angle_max - 1.0 < 1e-8, "{d:?}");
    assert!(d.area_max / d.area_min - 1.0 < 1e-8, "{d:?}");
}

/// A spherical cap has no isometric map to the plane; a conformal one
/// keeps angles to the mesh's resolution (measured: mean angle distortion
/// 1.026 at 8 x 8 quads, 1.013 at 16 x 16), and its factor varies across
/// the chart (lambda^2 from 0.88 to 1.14 of its mean).
#[test]
fn a_spherical_cap_maps_nearly_conformally_with_a_graded_factor() {
    let cap = |n: usize| {
        grid(n, n, 0.3, |s, t| {
            let (x, y) = (1.2 * s - 0.6, 1.2 * t - 0.6);
            Vector::new(x, y, (1.0 - x * x - y * y).sqrt())
        })
    };
    let coarse = ConformalChart::new(&cap(8)).expect("a chart").distortion();
    let fine = ConformalChart::new(&cap(16)).expect("a chart").distortion();
    eprintln!("spherical cap, 8 x 8 quads: {coarse:?}; 16 x 16: {fine:?}");
    assert!(
        fine.angle_mean < coarse.angle_mean,
        "{coarse:?} then {fine:?}"
    );
    assert!(fine.angle_mean < 1.02, "{fine:?}");
    assert!(
        fine.area_max / fine.area_min > 1.1,
        "a graded factor: {fine:?}"
    );
}

/// The chart is a quadtree's domain: its vertices lie inside, points far
/// off outside, its factor is the vertices' at the vertices, and a
/// quadtree over it builds with every point under three supports.
#[test]
fn a_chart_is_a_domain_for_the_quadtree() {
    let mesh = grid(12, 12, 0.3, |s, t| {
        let (x, y) = (1.2 * s - 0.6, 1.2 * t - 0.6);
        Vector::new(x, y, (1.0 - x * x - y * y).sqrt())
    });
    let chart = ConformalChart::new(&mesh).expect("a chart");
    let inner = 6 * 13 + 6;
    assert!(chart.distance(chart.uv()[inner]) < 0.0);
    let (lo, hi) = chart.bounds();
    assert!(chart.distance([hi[0] + 1.0, hi[1] + 1.0]) > 0.5);
    for k in [0usize, inner, 100] {
        let l = chart.lambda(chart.uv()[k]);
        assert!((l - chart.lambda_vertices()[k]).abs() < 1e-9, "vertex {k}");
    }
    let tree = Quadtree::build(&chart, lo, hi, &QuadtreeParams::new(0.1), &Cancel::new())
        .expect("a quadtree over the chart");
    let area: Real = tree
        .gauss_points()
        .iter()
        .map(|g| g.weight * chart.lambda(g.at).powi(2))
        .sum();
    let surface = mesh.area();
    assert!(
        (area / surface - 1.0).abs() < 0.05,
        "{area} against {surface}"
    );
}

/// Closed, degenerate and folded patches are refused with what to do.
#[test]
fn patches_that_are_not_disks_are_refused() {
    let tetrahedron = TriMesh {
        vertices: vec![Vector::zeros(), Vector::x(), Vector::y(), Vector::z()],
        triangles: vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    };
    let error = ConformalChart::new(&tetrahedron).expect_err("closed");
    assert!(
        matches!(
            error,
            ChartError::NotDisk {
                euler: 2,
                boundary: 0,
                ..
            }
        ),
        "{error}"
    );
    assert!(error.to_string().contains("cut the surface"));
    let mut flat = grid(3, 3, 0.0, |s, t| Vector::new(s, t, 0.0));
    flat.vertices[5] = flat.vertices[6];
    assert!(matches!(
        ConformalChart::new(&flat).expect_err("degenerate"),
        ChartError::Degenerate { .. }
    ));
}

/// The grid's answers are the whole chart's: the signed distance to the
/// boundary (exact near it, a lower bound far out), the triangle under a
/// point, and the surface point there (each vertex at its own place).
#[test]
fn the_grid_answers_as_a_scan_of_the_chart() {
    let mesh = grid(30, 20, 0.4, |s, t| {
        Vector::new(s, t, 0.3 * (2.0 * s).sin() * t)
    });
    let chart = ConformalChart::new(&mesh).expect("a disk");
    let (lo, hi) = chart.bounds();
    let scan = |u: Point2| {
        let nearest = chart
            .boundary()
            .iter()
            .map(|&[a, b]| segment_distance(u, chart.uv()[a as usize], chart.uv()[b as usize]))
            .fold(Real::INFINITY, Real::min);
        let inside = mesh.triangles.iter().any(|t| {
            let [a, b, c] = t.map(|k| chart.uv()[k as usize]);
            barycentric(u, a, b, c).is_some()
        });
        if inside { -nearest } else { nearest }
    };
    let span = [hi[0] - lo[0], hi[1] - lo[1]];
    for i in 0..=40 {
        for j in 0..=40 {
            let u = [
                lo[0] - 0.5 * span[0] + 2.0 * span[0] * i as Real / 40.0,
                lo[1] - 0.5 * span[1] + 2.0 * span[1] * j as Real / 40.0,
            ];
            let (fast, slow) = (chart.distance(u), scan(u));
            assert_eq!(fast.signum(), slow.signum(), "inside or out at {u:?}");
            assert!(fast.abs() <= slow.abs() + 1e-12, "a bound at {u:?}");
            if slow.abs() < 0.1 * span[0] {
                assert!(
                    (fast - slow).abs() < 1e-12,
                    "{fast} against {slow} at {u:?}"
                );
            }
        }
    }
    for (v, p) in mesh.vertices.iter().enumerate() {
        let at = chart.surface_point(chart.uv()[v]);
        assert!((at - p).norm() < 1e-9, "vertex {v}: {at} against {p}");
    }
}

/// Far outside the chart the distance is a bound that grows with the
/// point's distance, not a few grid cells however far it lies: a
/// quadtree over an atlas's plane prunes the empty plane by it (with a
/// bound of a few cells it kept every leaf around the charts, and their
/// nodes where a support reached a chart).
#[test]
fn a_far_point_is_known_to_be_far() {
    let mesh = grid(120, 80, 0.4, |s, t| Vector::new(s, t, 0.1 * s * t));
    let chart = ConformalChart::new(&mesh).expect("a disk");
    let (lo, hi) = chart.bounds();
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    for (dx, dy) in [(10.0, 0.0), (0.0, -7.0), (-4.0, 5.0), (3.0, 3.0)] {
        let u = [hi[0] + dx * span, hi[1] + dy * span];
        let out = [
            (lo[0] - u[0]).max(u[0] - hi[0]).max(0.0),
            (lo[1] - u[1]).max(u[1] - hi[1]).max(0.0),
        ];
        let to_box = out[0].hypot(out[1]);
        let d = chart.distance(u);
        assert!(d > 0.0, "outside at {u:?}");
        // The grid's box exceeds the map's by under a cell on each side.
        assert!(
            d >= to_box - 0.05 * span,
            "{d} for a point {to_box} off the box"
        );
    }
}
