//! Surface meshes against geometry nobody here chose: a ball and a slab of
//! lattice particles, whose colour-field surface should wrap the volume the
//! particles represent (`N dx^3`), and random fields that exercise every
//! corner configuration of the derived marching-cubes table.

use super::field::NodeGrid;
use super::*;
use crate::approx::KernelKind;
use crate::fluid::FluidParams;
use std::collections::HashMap;

/// Checks that `mesh` is closed and consistently oriented: every directed
/// edge appears in exactly one triangle and its reverse in exactly one
/// other, and no triangle repeats a vertex.
fn assert_closed_and_oriented(mesh: &TriMesh) {
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        assert!(
            tri[0] != tri[1] && tri[1] != tri[2] && tri[2] != tri[0],
            "triangle {t} repeats a vertex: {tri:?}"
        );
        for k in 0..3 {
            *directed.entry((tri[k], tri[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &count) in &directed {
        assert_eq!(count, 1, "edge {a}->{b} is in {count} triangles");
        assert_eq!(
            directed.get(&(b, a)),
            Some(&1),
            "edge {a}->{b} has no opposite half: the mesh is open or misoriented there"
        );
    }
    let used: std::collections::HashSet<u32> = mesh.triangles.iter().flatten().copied().collect();
    assert_eq!(used.len(), mesh.vertices.len(), "every vertex is used");
}

/// Lattice points `dx` apart (cell centres, as scenes place them) within
/// `radius` of the origin.
fn lattice_ball(radius: Real, dx: Real) -> Vec<Vector> {
    let n = (radius / dx).ceil() as i64 + 1;
    let mut points = Vec::new();
    for k in -n..n {
        for j in -n..n {
            for i in -n..n {
                let p = Vector::new(i as Real + 0.5, j as Real + 0.5, k as Real + 0.5) * dx;
                if p.norm() <= radius {
                    points.push(p);
                }
            }
        }
    }
    points
}

/// SPH densities `rho_i = sum_j m W_ij` by brute force, with the lattice
/// mass that makes the interior exactly `rho_0` (the fluid's own choice).
fn sph_volumes(positions: &[Vector], kernel: &Kernel, dx: Real) -> Vec<Real> {
    let mass = FluidParams::lattice_mass(dx, kernel, 1000.0);
    positions
        .iter()
        .map(|x| {
            let rho: Real = positions
                .iter()
                .map(|y| mass * kernel.value((x - y).norm()))
                .sum();
            mass / rho
        })
        .collect()
}

fn extractor(kernel: Kernel, cell: Real, min: Vector, max: Vector) -> SurfaceExtractor {
    SurfaceExtractor::new(kernel, cell, 0.5, min, max).expect("valid parameters")
}

/// A ball of 12 spacings' radius: the mesh is one closed, outward sphere,
/// its volume is the particles' volume `N dx^3` and every vertex lies near
/// the radius of the ball of that volume. Measured with rest volumes
/// (-0.7 %, vertices within 0.33 dx of that radius, the lattice's
/// staircase showing through) and with the fluid's SPH densities, lower at
/// the surface, whose larger volumes move it out (+3.9 %, radii from -0.21
/// to +0.45 dx).
#[test]
fn a_ball_of_particles_gives_a_closed_ball() {
    let dx = 0.01;
    let h = 2.0 * dx;
    let kernel = Kernel::new_3d(KernelKind::CubicSpline, h);
    let positions = lattice_ball(12.0 * dx, dx);
    let n = positions.len() as Real;
    let reference = n * dx.powi(3);
    let radius = (3.0 * reference / (4.0 * std::f64::consts::PI)).cbrt();
    let bound = Vector::repeat(0.2);
    let rest = vec![dx.powi(3); positions.len()];
    let sph = sph_volumes(&positions, &kernel, dx);
    for (label, volumes, volume_tol, band) in [
        ("rest volumes", &rest, 0.02, 0.4),
        ("SPH densities", &sph, 0.06, 0.5),
    ] {
        let mesh = extractor(kernel, 0.5 * dx, -bound, bound).extract(&positions, volumes);
        assert_closed_and_oriented(&mesh);
        // One sphere: Euler characteristic V - E + F = 2, with E = 3F/2.
        let euler = mesh.vertices.len() as i64 - mesh.triangles.len() as i64 / 2;
        assert_eq!(euler, 2, "{label}: not one closed sphere");
        let volume = mesh.signed_volume();
        let radii: Vec<Real> = mesh.vertices.iter().map(|v| v.norm()).collect();
        let (r_min, r_max) = radii
            .iter()
            .fold((Real::INFINITY, 0.0), |(a, b): (Real, Real), &r| {
                (a.min(r), b.max(r))
            });
        println!(
            "ball, {label}: {} particles, {} vertices, {} triangles; volume {:.4e} against \
             N dx^3 = {:.4e} ({:+.2} %); vertex radii in [{:.3}, {:.3}] dx around R = {:.3} dx",
            positions.len(),
            mesh.vertices.len(),
            mesh.triangles.len(),
            volume,
            reference,
            100.0 * (volume / reference - 1.0),
            r_min / dx,
            r_max / dx,
            radius / dx
        );
        assert!(
            (volume / reference - 1.0).abs() < volume_tol,
            "{label}: volume {volume} against {reference}"
        );
        assert!(
            (r_min - radius).abs() < band * dx && (r_max - radius).abs() < band * dx,
            "{label}: vertex radii [{r_min}, {r_max}] against {radius} +- {band} dx"
        );
    }
}

/// A slab of particles gives planar faces: the vertices on its top face,
/// away from its edges, lie on one plane half a spacing above the top
/// layer of particle centres, the boundary of the cells they fill.
#[test]
fn a_slab_gives_planar_faces() {
    let dx = 0.01;
    let h = 2.0 * dx;
    let kernel = Kernel::new_3d(KernelKind::CubicSpline, h);
    let (nx, ny, nz) = (20, 16, 6);
    let mut positions = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                positions.push(Vector::new(i as Real + 0.5, j as Real + 0.5, k as Real + 0.5) * dx);
            }
        }
    }
    let volumes = vec![dx.powi(3); positions.len()];
    let top = nz as Real * dx;
    let mesh = extractor(
        kernel,
        0.5 * dx,
        Vector::zeros(),
        Vector::new(nx as Real, ny as Real, nz as Real) * dx,
    )
    .extract(&positions, &volumes);
    assert_closed_and_oriented(&mesh);
    let inner =
        |v: &Vector| v.x > h && v.x < nx as Real * dx - h && v.y > h && v.y < ny as Real * dx - h;
    let heights: Vec<Real> = mesh
        .vertices
        .iter()
        .filter(|v| inner(v) && v.z > 0.5 * top)
        .map(|v| v.z)
        .collect();
    let (lo, hi) = heights
        .iter()
        .fold((Real::INFINITY, -Real::INFINITY), |(a, b), &z| {
            (a.min(z), b.max(z))
        });
    println!(
        "slab top: {} vertices at heights [{:.4}, {:.4}] dx against {:.1} dx",
        heights.len(),
        lo / dx,
        hi / dx,
        top / dx
    );
    assert!(heights.len() > 100);
    assert!(hi - lo < 0.01 * dx, "top face not planar: [{lo}, {hi}]");
    assert!(
        (0.5 * (lo + hi) - top).abs() < 0.05 * dx,
        "top at {lo}..{hi}"
    );
    // Every triangle of the top face faces up.
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = mesh.corners(t);
        if tri.iter().all(|&v| {
            let v = &mesh.vertices[v as usize];
            inner(v) && v.z > 0.5 * top
        }) {
            let normal = (b - a).cross(&(c - a));
            assert!(
                normal.z > 0.99 * normal.norm(),
                "triangle {t}: normal {normal:?}"
            );
        }
    }
}

/// Random values on a grid whose border is outside: whatever the mix of
/// corner configurations (all 256 appear), the mesh is closed and
/// consistently oriented.
#[test]
fn random_fields_give_closed_oriented_meshes() {
    let mut seed: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut next = move || {
        // xorshift64*: a fixed, seeded sequence.
        seed ^= seed >> 12;
        seed ^= seed << 25;
        seed ^= seed >> 27;
        (seed.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32
    };
    let n = 14;
    let mut seen = [false; 256];
    for _ in 0..4 {
        let mut values = vec![0.0f32; n * n * n];
        for k in 1..n - 1 {
            for j in 1..n - 1 {
                for i in 1..n - 1 {
                    values[i + n * (j + n * k)] = next();
                }
            }
        }
        let grid = NodeGrid {
            origin: Vector::zeros(),
            cell: 1.0,
            dims: [n, n, n],
            values,
        };
        for k in 0..n - 1 {
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let mut case = 0;
                    for c in 0..8 {
                        let (di, dj, dk) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
                        if grid.values[i + di + n * (j + dj + n * (k + dk))] > 0.5 {
                            case |= 1 << c;
                        }
                    }
                    seen[case] = true;
                }
            }
        }
        let mesh = marching_cubes::extract(&grid, 0.5);
        assert_closed_and_oriented(&mesh);
        assert!(mesh.signed_volume() > 0.0);
    }
    let missing: Vec<usize> = (0..256).filter(|&c| !seen[c]).collect();
    assert!(missing.is_empty(), "cases never met: {missing:?}");
}

/// No particles, or particles all of zero volume, give an empty mesh.
#[test]
fn empty_fluid_gives_an_empty_mesh() {
    let kernel = Kernel::new_3d(KernelKind::CubicSpline, 0.02);
    let surface = extractor(kernel, 0.005, Vector::zeros(), Vector::repeat(1.0));
    assert_eq!(surface.extract(&[], &[]), TriMesh::default());
    let mesh = surface.extract(&[Vector::repeat(0.5)], &[0.0]);
    assert!(mesh.triangles.is_empty() && mesh.vertices.is_empty());
}

/// The mesh does not depend on the thread count.
#[test]
fn meshes_do_not_depend_on_threads() {
    let dx = 0.01;
    let kernel = Kernel::new_3d(KernelKind::WendlandC2, 2.0 * dx);
    let positions = lattice_ball(6.0 * dx, dx);
    let volumes = vec![dx.powi(3); positions.len()];
    let surface = extractor(kernel, 0.5 * dx, Vector::repeat(-0.1), Vector::repeat(0.1));
    let all = surface.extract(&positions, &volumes);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool")
        .install(|| surface.extract(&positions, &volumes));
    assert_eq!(all, one);
}

/// Bad parameters and oversized regions are refused with the reason.
#[test]
fn bad_parameters_are_refused() {
    let kernel = Kernel::new_3d(KernelKind::CubicSpline, 0.02);
    let (min, max) = (Vector::zeros(), Vector::repeat(1.0));
    for cell in [0.0, -1.0, Real::NAN, Real::INFINITY] {
        assert!(matches!(
            SurfaceExtractor::new(kernel, cell, 0.5, min, max),
            Err(SurfaceError::Cell(_))
        ));
    }
    for iso in [0.0, 1.0, -0.5, Real::NAN] {
        assert!(matches!(
            SurfaceExtractor::new(kernel, 0.01, iso, min, max),
            Err(SurfaceError::Iso(_))
        ));
    }
    let err = SurfaceExtractor::new(kernel, 1e-4, 0.5, min, max).expect_err("10^12 nodes");
    assert!(matches!(err, SurfaceError::TooManyNodes { .. }), "{err}");
}

/// Through a scene: frames carry the surface only when `output.surface`
/// names it, and a block of fluid in a corner of the domain (walls on
/// three sides) is wrapped whole, its volume that of the block.
#[test]
fn frames_carry_a_surface_only_when_asked() {
    let text = r#"
        [domain]
        min = [0.0, 0.0, 0.0]
        max = [0.5, 0.5, 0.5]
        [time]
        dt = 0.005
        [output]
        surface = {}
        [[systems]]
        kind = "fluid"
        spacing = 0.02
        stiffness = 2.0e4
        [[systems.blocks]]
        region = { min = [0.0, 0.0, 0.0], max = [0.2, 0.2, 0.2] }
    "#;
    let scene = crate::scene::Scene::from_toml_str(text).expect("valid");
    let mut world = scene
        .build(&crate::scene::BuildOptions::default())
        .expect("world");
    world.step().expect("a step");
    let mesh = world.frame().surface.expect("asked for");
    assert_closed_and_oriented(&mesh);
    let volume = mesh.signed_volume();
    println!(
        "block 0.2 m in a corner: {} triangles, volume {volume:.5e} m^3 against 8e-3 ({:+.2} %)",
        mesh.triangles.len(),
        100.0 * (volume / 8e-3 - 1.0)
    );
    assert!((volume / 8e-3 - 1.0).abs() < 0.05, "{volume}");

    let mut plain = scene.clone();
    plain.output.surface = None;
    let world = plain
        .build(&crate::scene::BuildOptions::default())
        .expect("world");
    assert_eq!(world.frame().surface, None);
}
