//! EFG solids and their modal systems at the edges of their inputs:
//! nearly incompressible and extremely stiff or soft materials, huge and
//! tiny time steps, a plate thinner than the octree's cells, and a solid
//! built from a noisy oriented point cloud.

use super::super::*;
use crate::cancel::Cancel;
use crate::geometry::{
    ImplicitSurface, MeshSdf, OctreeError, PointSurface, PointSurfaceParams, TriMesh,
};
use crate::linalg::eigen::Modes;
use crate::math::{Real, Vector};
use crate::modal::{Damping, ModalSystem};
use crate::testing::perturb_normals;
use nalgebra::DVector;

/// A clamped `l x h x h` cantilever (clamped on `x = 0`).
fn cantilever(l: Real, h: Real) -> (MeshSdf, FixedSurface) {
    let mesh = TriMesh::cuboid(Vector::zeros(), Vector::new(l, h, h)).subdivided(3);
    let fixed = FixedSurface::of_mesh_in_box(
        &mesh,
        &Vector::repeat(-1e-9),
        &Vector::new(1e-9, h + 1e-9, h + 1e-9),
    );
    (MeshSdf::new(&mesh).expect("closed"), fixed)
}

fn material(young: Real, poisson: Real) -> Material {
    Material {
        density: 1000.0,
        young,
        poisson,
    }
}

fn modes_of(
    sdf: &MeshSdf,
    fixed: &FixedSurface,
    material: Material,
    cell: Real,
    count: usize,
) -> Result<(EfgSolid, Modes), EfgError> {
    let solid = EfgSolid::build(sdf, fixed, material, EfgParams::new(cell), &Cancel::new())?;
    let modes = solid.modes(count, 1e-10, &Cancel::new())?;
    Ok((solid, modes))
}

/// A clamped 4 x 1 x 1 beam (cell 0.5, 81 nodes, E = 1e6 Pa) at
/// Poisson's ratios 0.3, 0.45, 0.49 and 0.4999 (`lambda / mu` from 1.5 to
/// 5000). The modes must stay a finite, positive spectrum that a modal
/// basis accepts (or the build fail with a clear [`EfgError`]; measured:
/// every ratio builds).
///
/// - Bending: the linear displacement formulation locks volumetrically
///   as `nu -> 0.5`, so the first (bending) frequency rises with `nu`
///   (beam theory's `sqrt(E I / rho A)` would not move): measured 2.243,
///   2.312, 2.485, 4.720 rad/s; asserted strictly increasing.
/// - Torsion changes no volume, so it does not lock: its frequency
///   follows `sqrt(G) = sqrt(E / 2 (1 + nu))`, asserted to 1 % of that
///   ratio against nu = 0.3 (measured within 0.15 %). The torsion mode
///   is the one whose rotation vectors (W) point along the beam's axis.
#[test]
fn nearly_incompressible_beams_give_finite_modes_that_stiffen_with_poisson_ratio() {
    let (sdf, fixed) = cantilever(4.0, 1.0);
    let mut first = Vec::new();
    let mut torsion = Vec::new();
    for nu in [0.3, 0.45, 0.49, 0.4999] {
        let (solid, modes) = modes_of(&sdf, &fixed, material(1e6, nu), 0.5, 6)
            .unwrap_or_else(|e| panic!("nu {nu}: {e}"));
        let omega: Vec<Real> = modes.eigenvalues.iter().map(|l| l.sqrt()).collect();
        println!(
            "nu {nu}: {} nodes, omega {omega:.4?} rad/s",
            solid.nodes().len()
        );
        assert_eq!(modes.zero_modes, 0);
        assert!(
            modes.eigenvalues.iter().all(|l| l.is_finite() && *l > 0.0),
            "{:?}",
            modes.eigenvalues
        );
        let (_, basis) = solid
            .modal_basis(6, 1e-10, &Cancel::new())
            .expect("a valid basis");
        assert_eq!(basis.mode_count(), 6);
        first.push(omega[0]);
        let w = solid.rotation_modes(&modes).expect("rotation modes");
        let along_x = |j: usize| {
            let column = w.column(j);
            let x: Real = column.iter().step_by(3).map(|v| v * v).sum();
            x / column.norm_squared()
        };
        let j = (0..6).find(|&j| along_x(j) > 0.9).expect("a torsion mode");
        torsion.push((nu, omega[j]));
    }
    println!("first (bending) omega {first:.4?}; torsion (nu, omega) {torsion:.4?}");
    assert!(first.windows(2).all(|w| w[1] > w[0]), "{first:?}");
    let (nu0, omega0) = torsion[0];
    for &(nu, omega) in &torsion[1..] {
        let expected = ((1.0 + nu0) / (1.0 + nu)).sqrt();
        let ratio = omega / omega0;
        assert!(
            (ratio / expected - 1.0).abs() < 0.01,
            "nu {nu}: torsion ratio {ratio}, sqrt(G) ratio {expected}"
        );
    }
}

/// The same clamped beam at E = 1e-2, 1e6 and 1e12 Pa: K (and the
/// penalty, `1e4 E / cell`) scale with E and M does not, so every
/// eigenvalue scales exactly with E and every frequency with sqrt(E).
/// Asserted for the 6 lowest modes to 1e-6 relative (the eigensolver's
/// tolerance is 1e-10 on the eigenvalues); the measured worst is printed.
#[test]
fn frequencies_scale_as_the_square_root_of_youngs_modulus_over_fourteen_decades() {
    let (sdf, fixed) = cantilever(4.0, 1.0);
    let reference = modes_of(&sdf, &fixed, material(1e6, 0.3), 0.5, 6)
        .expect("modes")
        .1;
    for young in [1e-2, 1e12] {
        let (solid, modes) = modes_of(&sdf, &fixed, material(young, 0.3), 0.5, 6).expect("modes");
        let worst = modes
            .eigenvalues
            .iter()
            .zip(&reference.eigenvalues)
            .map(|(l, r)| ((l / young).sqrt() / (r / 1e6).sqrt() - 1.0).abs())
            .fold(0.0, Real::max);
        println!(
            "E {young:e}: omega_1 {:.6e} rad/s (sqrt(E) scaling predicts {:.6e}); worst relative \
             deviation over 6 modes {worst:.1e}",
            modes.eigenvalues[0].sqrt(),
            (reference.eigenvalues[0] * young / 1e6).sqrt()
        );
        assert!(worst < 1e-6, "E {young}: {worst:e}");
        // A modal basis accepts them too (E = 1e-2 puts the eigenvalues
        // near 1e-8, the floor of the rigid-mode allowance).
        let (_, basis) = solid.modal_basis(6, 1e-10, &Cancel::new()).expect("basis");
        assert!(basis.eigenvalues().iter().all(|l| *l > 0.0));
    }
}

/// Huge (h = 100 s) and tiny (h = 1e-9 s) steps of a clamped 4 x 1 x 1
/// beam (E = 1e7 Pa, 12 modes) under gravity, warping off and on.
///
/// Backward Euler from rest under a constant modal force `f_j` moves each
/// amplitude toward its static value `z*_j = f_j / lambda_j`, the error
/// multiplied per step by a root of modulus `1 / sqrt(1 + h c_j + h^2
/// lambda_j) < 1 / (h sqrt(lambda_1)) = 1.4e-3` at `h = 100 s`; the roots
/// are complex (`c_j^2 < 4 lambda_j`), so the first overshoot past `z*_j`
/// is about its square, 2e-6 (measured 2.0e-6, printed). Asserted:
/// `|z_j| <= (1 + 1e-5) |z*_j|` at every step and `|z - z*| < 1e-9 |z*|`
/// after 20 steps, and the warped run's largest nodal
/// displacement within 1 % of the linear static one's (the tip sags 7 %
/// of the length, so the rotation is moderate; measured -0.44 %) and
/// settled.
///
/// At h = 1e-9 s, 1000 steps reach t = 1e-6 s, far below the first period
/// (about 1 s): the exact motion is free fall `f t^2 / 2`, and backward
/// Euler's `f h^2 n (n + 1) / 2` is larger by `(n + 1) / n`. Rayleigh
/// damping (`alpha = 0.5`, `beta = 1e-3`) slows it by `c_j t / 3` to first
/// order (`c_j = alpha + beta lambda_j`, at most 1.5e-5 over the 12
/// modes): the amplitudes asserted within half the largest `c_j t` of it
/// (relative, as a vector; measured 1.3e-6), finite, and below the static
/// displacement (and, without warping, each amplitude below its static
/// value).
#[test]
fn huge_and_tiny_time_steps_stay_finite_and_below_the_static_solution() {
    let (sdf, fixed) = cantilever(4.0, 1.0);
    let solid = EfgSolid::build(
        &sdf,
        &fixed,
        material(1e7, 0.3),
        EfgParams::new(0.5),
        &Cancel::new(),
    )
    .expect("solid");
    let (modes, basis) = solid.modal_basis(12, 1e-10, &Cancel::new()).expect("basis");
    let nodes = solid.nodes().len();
    let gravity: Vec<Vector> = solid
        .node_masses()
        .iter()
        .map(|m| Vector::new(0.0, 0.0, -9.81) * *m)
        .collect();
    let n = 3 * nodes;
    let flat: Vec<Real> = gravity.iter().flat_map(|f| [f.x, f.y, f.z]).collect();
    let force: Vec<Real> = (0..modes.eigenvalues.len())
        .map(|j| {
            modes.vectors[j * n..(j + 1) * n]
                .iter()
                .zip(&flat)
                .map(|(a, b)| a * b)
                .sum()
        })
        .collect();
    let statics = DVector::from_iterator(
        force.len(),
        force.iter().zip(&modes.eigenvalues).map(|(f, l)| f / l),
    );
    let damping = Damping::new(0.5, 1e-3).expect("damping");
    let largest = |system: &ModalSystem| {
        system
            .displacements()
            .iter()
            .map(|v| v.norm())
            .fold(0.0, Real::max)
    };
    let mut linear_static = ModalSystem::new(basis.clone(), damping, false);
    linear_static
        .set_state(&statics, &DVector::zeros(statics.len()))
        .expect("state");
    let static_largest = largest(&linear_static);

    // Huge steps.
    let mut last_largest = Vec::new();
    let mut overshoot: Real = 0.0;
    for warping in [false, true] {
        let mut system = ModalSystem::new(basis.clone(), damping, warping);
        let mut previous = 0.0;
        for step in 0..20 {
            system.step(100.0, &gravity).expect("step");
            let z = system.amplitudes();
            assert!(z.iter().all(|v| v.is_finite()));
            if !warping {
                // A mode gravity does not load (an antisymmetric one) has
                // a static amplitude of rounding size: allow rounding of
                // the largest.
                let rounding = 1e-12 * statics.amax();
                for (j, (a, s)) in z.iter().zip(statics.iter()).enumerate() {
                    if s.abs() > rounding {
                        overshoot = overshoot.max(a.abs() / s.abs() - 1.0);
                    }
                    assert!(
                        a.abs() <= s.abs() * (1.0 + 1e-5) + rounding,
                        "step {step}, mode {j}: {a:e} over {s:e}"
                    );
                }
            }
            let now = largest(&system);
            if step == 19 {
                println!(
                    "h = 100 s, warping {warping}: largest displacement {now:.6} (linear static \
                     {static_largest:.6}), last change {:.1e}, |z - z*| / |z*| {:.1e}, largest \
                     overshoot of a linear amplitude past its static value {overshoot:.1e}",
                    (now - previous).abs(),
                    (z - &statics).norm() / statics.norm()
                );
                if !warping {
                    assert!((z - &statics).norm() < 1e-9 * statics.norm());
                }
                assert!((now - previous).abs() < 1e-9 * now);
            }
            previous = now;
        }
        last_largest.push(previous);
    }
    assert!(
        (last_largest[1] / static_largest - 1.0).abs() < 0.01,
        "{last_largest:?} vs {static_largest}"
    );

    // Tiny steps. Damping slows the fall by `c_j t / 3` to first order,
    // `c_j = alpha + beta lambda_j`.
    let (h, steps) = (1e-9, 1000);
    let damped = (damping.alpha() + damping.beta() * modes.eigenvalues[11]) * h * steps as Real;
    for warping in [false, true] {
        let mut system = ModalSystem::new(basis.clone(), damping, warping);
        for _ in 0..steps {
            system.step(h, &gravity).expect("step");
        }
        let z = system.amplitudes();
        let t = h * steps as Real;
        let scale = (steps + 1) as Real / steps as Real;
        let fall =
            DVector::from_iterator(force.len(), force.iter().map(|f| 0.5 * f * t * t * scale));
        let deviation = (z - &fall).norm() / fall.norm();
        let now = largest(&system);
        println!(
            "h = 1e-9 s, warping {warping}: after {steps} steps |z| {:.4e}, largest displacement \
             {now:.3e}; relative deviation from backward Euler's free fall {deviation:.1e} \
             (largest damping c t {damped:.1e})",
            z.norm()
        );
        assert!(z.iter().all(|v| v.is_finite()));
        assert!(deviation < 0.5 * damped, "{deviation:e}");
        assert!(now < static_largest);
        if !warping {
            assert!(
                z.iter()
                    .zip(statics.iter())
                    .all(|(a, s)| a.abs() <= s.abs())
            );
        }
    }
}

/// A 2 x 2 plate of thickness `t` meshed with cells of 0.25. The octree's
/// root is placed so that the plate's lower face runs through octant
/// centres, and boundary octants carry 2 x 2 x 2 Gauss points on each of
/// their 2 x 2 x 2 integration cells: in the layer of octants on the
/// lower face, at z = 0.026 and 0.099 above it; in the next, at 0.151 and
/// 0.224. What each thickness gives, asserted variant by variant:
///
/// - `t` = 1e-9 and 0.01 (1/25 of a cell): no Gauss point inside, so
///   [`OctreeError::Empty`] ("the solid is thinner than a cell; use a
///   smaller cell"). Before this test such a plate built a solid with
///   nodes but no quadrature point (volume 0), whose modes then failed
///   with an eigensolver "shift NaN" error;
/// - `t` = 0.075 (0.3 cells): Gauss points inside but every node in the
///   plane z = 0 (the layer above is wholly outside): no linear MLS fit,
///   [`CoverError::Uncovered`] with its 4 coplanar supports;
/// - `t` = 0.15 (0.6 cells): two layers of nodes, it builds, with 6 rigid
///   modes for the free plate, but only the points below z = 0.125 are
///   inside, so the quadrature's volume is 0.125 / 0.15 of the plate's:
///   -1/6, asserted to 1e-9 (the resolution of a cut cell is its Gauss
///   points');
/// - `t` = 0.25 and 0.5 (1 and 2 cells): the volume exact to 1e-9 and 6
///   rigid modes.
///
/// Never a panic.
#[test]
fn a_plate_thinner_than_a_cell_is_refused_with_a_clear_error_and_a_thicker_one_builds() {
    let cell = 0.25;
    let build = |t: Real| {
        let mesh = TriMesh::cuboid(Vector::zeros(), Vector::new(2.0, 2.0, t));
        let sdf = MeshSdf::new(&mesh).expect("closed");
        EfgSolid::build(
            &sdf,
            &FixedSurface::default(),
            material(1e6, 0.3),
            EfgParams::new(cell),
            &Cancel::new(),
        )
    };
    for t in [1e-9, 0.04 * cell] {
        let e = build(t).expect_err("thinner than the Gauss points");
        println!("thickness {t}: {e}");
        assert!(
            matches!(e, EfgError::Octree(OctreeError::Empty { .. })),
            "{e:?}"
        );
    }
    let e = build(0.3 * cell).expect_err("one plane of nodes");
    println!("thickness {}: {e}", 0.3 * cell);
    assert!(
        matches!(
            e,
            EfgError::Cover(CoverError::Uncovered { supports: 4, .. })
        ),
        "{e:?}"
    );
    for (ratio, expected) in [(0.6, -1.0 / 6.0), (1.0, 0.0), (2.0, 0.0)] {
        let t = ratio * cell;
        let solid = build(t).expect("two layers of nodes or more");
        let volume = solid.volume() / (4.0 * t) - 1.0;
        let modes = solid.modes(8, 1e-10, &Cancel::new()).expect("modes");
        println!(
            "thickness {t}: {} nodes, volume {volume:+.3e}, {} zero modes, first elastic omega \
             {:.4} rad/s",
            solid.nodes().len(),
            modes.zero_modes,
            modes.eigenvalues[6].sqrt()
        );
        assert!(
            (volume - expected).abs() < 1e-9,
            "thickness {t}: {volume:e}"
        );
        assert_eq!(modes.zero_modes, 6, "{:?}", modes.eigenvalues);
    }
}

/// Oriented points on the faces of the box `[0, size]`, `spacing` apart
/// on a grid shifted half a spacing in from the edges.
fn box_points(size: Vector, spacing: Real) -> (Vec<Vector>, Vec<Vector>) {
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let (nu, nv) = (
            (size[u] / spacing).round() as usize,
            (size[v] / spacing).round() as usize,
        );
        for side in [0.0, 1.0] {
            for i in 0..nu {
                for j in 0..nv {
                    let mut p = Vector::zeros();
                    p[axis] = side * size[axis];
                    p[u] = (i as Real + 0.5) * size[u] / nu as Real;
                    p[v] = (j as Real + 0.5) * size[v] / nv as Real;
                    let mut n = Vector::zeros();
                    n[axis] = if side > 0.0 { 1.0 } else { -1.0 };
                    points.push(p);
                    normals.push(n);
                }
            }
        }
    }
    (points, normals)
}

/// EFG solids from noisy oriented point clouds (normals turned by up to
/// 15 degrees) through [`PointSurface`]: a unit sphere (3,000 Fibonacci
/// points, spacing 0.062) and a 2 x 1 x 1 box (points 0.05 apart on its
/// faces), cell 0.25, free. References: the exact volumes.
///
/// - Sphere, 4 pi / 3: the quadrature of a mesh's ball is right to 3e-3
///   at this cell (`the_quadrature_measures_the_volume_of_a_ball`), and
///   the fitted field's curvature bias is about `0.07 (h / R)^2 R`, with
///   supports `h` near 0.22: 0.35 % of the radius, 1 % of the volume.
///   Measured +1.33 %; asserted within 2 %.
/// - Box, 2: its faces run through octant centres, so along integration
///   cell boundaries, and every Gauss point is at least 0.026 (half a
///   sample spacing) from them: the quadrature's volume is exact if and
///   only if the noisy field puts every point on the right side. Measured
///   exact; asserted to 1e-9.
///
/// Free bodies: exactly 6 zero modes, each below 1e-8 of the first
/// elastic eigenvalue (measured 1e-15).
#[test]
fn noisy_point_clouds_make_solids_with_the_right_volume_and_six_rigid_modes() {
    let mut seed = 7;
    let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
    let count = 3000;
    let sphere: Vec<Vector> = (0..count)
        .map(|i| {
            let z = 1.0 - (2 * i + 1) as Real / count as Real;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as Real;
            Vector::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect();
    let sphere_normals = perturb_normals(&sphere, 15.0, &mut seed);
    let (box_p, box_n) = box_points(Vector::new(2.0, 1.0, 1.0), 0.05);
    let box_n = perturb_normals(&box_n, 15.0, &mut seed);
    let cases = [
        (
            "sphere",
            sphere,
            sphere_normals,
            4.0 / 3.0 * std::f64::consts::PI,
            0.02,
        ),
        ("box", box_p, box_n, 2.0, 1e-9),
    ];
    for (name, points, normals, exact, tolerance) in cases {
        let surface =
            PointSurface::new(&points, &normals, PointSurfaceParams::default()).expect("surface");
        let solid = EfgSolid::build(
            &surface as &dyn ImplicitSurface,
            &FixedSurface::default(),
            material(1e6, 0.3),
            EfgParams::new(0.25),
            &Cancel::new(),
        )
        .expect("solid");
        let modes = solid.modes(10, 1e-10, &Cancel::new()).expect("modes");
        let volume = solid.volume() / exact - 1.0;
        let first_elastic = modes.eigenvalues[6];
        let rigid = modes.eigenvalues[..6]
            .iter()
            .map(|l| l.abs())
            .fold(0.0, Real::max);
        println!(
            "{name}: {} points, spacing {:.4}, {} nodes, volume {:+.3e}, {} zero modes, \
             largest |lambda| of the rigid ones {:.1e} of the first elastic {first_elastic:.4e}",
            points.len(),
            surface.spacing(),
            solid.nodes().len(),
            volume,
            modes.zero_modes,
            rigid / first_elastic
        );
        assert!(volume.abs() < tolerance, "{name}: {volume:e}");
        assert_eq!(modes.zero_modes, 6, "{name}: {:?}", modes.eigenvalues);
        assert!(rigid < 1e-8 * first_elastic, "{name}: {rigid:e}");
    }
}
