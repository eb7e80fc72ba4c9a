use super::*;
use crate::testing::fibonacci_sphere;
use std::f64::consts::PI;

fn euler_characteristic(mesh: &TriMesh) -> i64 {
    let report = mesh.edge_report();
    mesh.vertices.len() as i64 - report.edges as i64 + mesh.triangles.len() as i64
}

/// The manifold, orientation and piece checks every reconstruction must
/// pass.
fn assert_manifold(mesh: &TriMesh) {
    let report = mesh.edge_report();
    assert_eq!(report.non_manifold, 0, "no edge on three triangles");
    assert_eq!(report.misoriented, 0, "consistently oriented");
    let mut used = vec![false; mesh.vertices.len()];
    mesh.triangles
        .iter()
        .flatten()
        .for_each(|&v| used[v as usize] = true);
    assert!(used.iter().all(|&u| u), "no unused vertex");
}

/// A unit sphere's 2,000 samples mesh to a closed genus-0 surface within
/// 1 % of the radius, facing out (positive volume within 2 % of 4/3 pi).
#[test]
fn a_sampled_sphere_meshes_closed_on_the_sphere() {
    let points = fibonacci_sphere(2000);
    let built = reconstruct(&points, &points, 0.1, &Cancel::new()).expect("a sphere");
    let mesh = &built.mesh;
    assert_manifold(mesh);
    assert!(mesh.is_closed(), "no rim");
    assert_eq!(euler_characteristic(mesh), 2, "a sphere's topology");
    assert_eq!(built.dropped, 0);
    let worst = mesh
        .vertices
        .iter()
        .map(|v| (v.norm() - 1.0).abs())
        .fold(0.0, Real::max);
    assert!(worst < 0.01, "vertices within {worst} of the sphere");
    let volume = mesh.signed_volume() / (4.0 / 3.0 * PI);
    assert!((volume - 1.0).abs() < 0.02, "volume ratio {volume}");
}

/// A torus's samples (genus 1) mesh to a closed surface of Euler
/// characteristic 0.
#[test]
fn a_sampled_torus_keeps_its_handle() {
    let (big, small) = (1.0, 0.4);
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for i in 0..120 {
        for j in 0..48 {
            let (u, v) = (2.0 * PI * i as Real / 120.0, 2.0 * PI * j as Real / 48.0);
            let n = Vector::new(u.cos() * v.cos(), u.sin() * v.cos(), v.sin());
            points.push(Vector::new(big * u.cos(), big * u.sin(), 0.0) + small * n);
            normals.push(n);
        }
    }
    let built = reconstruct(&points, &normals, 0.06, &Cancel::new()).expect("a torus");
    assert_manifold(&built.mesh);
    assert!(built.mesh.is_closed());
    assert_eq!(euler_characteristic(&built.mesh), 0, "a torus's topology");
}

/// An open disk's samples (a sunflower spiral, normals up) mesh to a
/// disk in their plane, facing up, whose rim lies within the kept reach
/// past the outermost samples.
#[test]
fn a_sampled_disk_meshes_open_with_one_rim() {
    let count = 2000;
    let golden = PI * (3.0 - 5.0_f64.sqrt());
    let points: Vec<Vector> = (0..count)
        .map(|i| {
            let (r, phi) = (
                ((i as Real + 0.5) / count as Real).sqrt(),
                golden * i as Real,
            );
            Vector::new(r * phi.cos(), r * phi.sin(), 0.0)
        })
        .collect();
    let normals = vec![Vector::z(); count];
    let cell = 0.05;
    let built = reconstruct(&points, &normals, cell, &Cancel::new()).expect("a disk");
    let mesh = &built.mesh;
    assert_manifold(mesh);
    assert_eq!(euler_characteristic(mesh), 1, "a disk's topology");
    // Every plane of the cloud is z = 0, so the field is z: only the
    // snap moves a vertex off the plane.
    for v in &mesh.vertices {
        assert!(v.z.abs() <= 1.01 * SNAP * cell, "off the plane by {}", v.z);
    }
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t);
        assert!((b - a).cross(&(c - a)).z > 0.0, "facing the normals");
    }
    let mut uses: HashMap<(u32, u32), usize> = HashMap::new();
    for tri in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let rim: Vec<Real> = uses
        .iter()
        .filter(|&(_, &n)| n == 1)
        .flat_map(|(&(a, b), _)| [a, b])
        .map(|v| mesh.vertices[v as usize].xy().norm())
        .collect();
    let (inner, outer) = rim
        .iter()
        .fold((Real::INFINITY, 0.0), |(lo, hi): (Real, Real), &r| {
            (lo.min(r), hi.max(r))
        });
    assert!(inner > 1.0 - cell, "rim inside the samples at {inner}");
    assert!(
        outer < 1.0 + RIM_SPACINGS * built.spacing + cell,
        "rim past the reach at {outer} (spacing {})",
        built.spacing
    );
}

/// Two balls far apart are two surfaces, refused by name.
#[test]
fn two_separate_balls_are_refused() {
    let one = fibonacci_sphere(600);
    let points: Vec<Vector> = one
        .iter()
        .copied()
        .chain(one.iter().map(|p| p + Vector::x() * 4.0))
        .collect();
    let normals: Vec<Vector> = one.iter().chain(&one).copied().collect();
    let error = reconstruct(&points, &normals, 0.15, &Cancel::new()).expect_err("two pieces");
    assert_eq!(error, ReconstructError::Pieces { pieces: 2 });
    assert!(error.to_string().contains("its own shell"), "{error}");
}

/// A bad cell, a grid past the limit, inward normals and cancellation
/// each get their error.
#[test]
fn bad_requests_are_refused() {
    let points = fibonacci_sphere(600);
    for cell in [0.0, -1.0, Real::NAN] {
        assert!(matches!(
            reconstruct(&points, &points, cell, &Cancel::new()),
            Err(ReconstructError::Cell(_))
        ));
    }
    // A cell under the spacing is raised to it; a cloud whose box is
    // ten thousand spacings wide (most samples on a unit ball, a few on
    // one a thousand times larger) still needs too many nodes.
    let fine = reconstruct(&points, &points, 1e-3, &Cancel::new()).expect("a sphere");
    assert_eq!(fine.cell, fine.spacing);
    let (wide, wide_normals): (Vec<Vector>, Vec<Vector>) = points
        .iter()
        .map(|p| (*p, *p))
        .chain(points[..200].iter().map(|p| (p * 1000.0, *p)))
        .unzip();
    assert!(matches!(
        reconstruct(&wide, &wide_normals, 1e-3, &Cancel::new()),
        Err(ReconstructError::TooManyNodes { .. })
    ));
    let cancel = Cancel::new();
    cancel.cancel();
    assert_eq!(
        reconstruct(&points, &points, 0.1, &cancel).map(|r| r.dropped),
        Err(ReconstructError::Cancelled)
    );
    assert!(matches!(
        reconstruct(&points[..3], &points[..3], 0.1, &Cancel::new()),
        Err(ReconstructError::Cloud(_))
    ));
}

/// Two triangles that touch at one corner are split there.
#[test]
fn a_pinched_vertex_is_split() {
    let mesh = TriMesh {
        vertices: vec![
            Vector::zeros(),
            Vector::x(),
            Vector::y(),
            -Vector::x(),
            -Vector::y(),
            Vector::z(),
        ],
        triangles: vec![[0, 1, 2], [0, 3, 4]],
    };
    let split = split_pinched_vertices(mesh);
    assert_eq!(
        split.vertices.len(),
        6,
        "the unused vertex dropped, the pinch doubled"
    );
    assert_ne!(split.triangles[0][0], split.triangles[1][0]);
    assert_eq!(
        split.vertices[split.triangles[1][0] as usize],
        Vector::zeros()
    );
}
